//! The transmit queues: where the port writes each frame in place, in
//! contiguous room (a bip buffer: a frame that does not fit before the
//! buffer's end goes to its start, and the bytes it skipped are never
//! sent), and whence the bytes go out in contiguous runs.
//!
//! Two of them, behind one [`TxQueue`]: the board's [`TxBuffer`]
//! (`bbqueue`'s lock-free single-producer single-consumer bip buffer),
//! whose reading end is the UART's interrupt and its DMA stream, which
//! send the frames from where the port wrote them; and [`ByteRing`], a
//! port's own queue where one loop both queues and sends (the host's
//! tools and tests, the benches), drained through [`ByteRing::front`].
//!
//! Why no byte queues: `heapless::Deque` and `heapless::spsc::Queue` move
//! one byte per call, which measured 2 000 instructions per sample frame
//! on the Cortex-M4 (`cargo xtask bench`, whole loop), paid inside the
//! sample task before its frame counted as queued; a ring that took a
//! frame in two pieces around its end cost a copy of every frame that met
//! the end (about 450 instructions once every 43 frames).

/// Where a port queues its frames: contiguous room, written in place.
pub trait TxQueue {
    /// Contiguous room for at least `n` bytes, handed to `write`, which
    /// returns how many of them it used (those are queued) or an error
    /// (nothing is); `None` where no such room is free.
    fn put<E>(
        &mut self,
        n: usize,
        write: impl FnOnce(&mut [u8]) -> Result<usize, E>,
    ) -> Option<Result<usize, E>>;
}

/// The board's transmit queue, `N` bytes: the port writes frames into it
/// from the sample task and the background (one producer: they share it
/// under the link's lock), the UART's interrupt reads them (the one
/// consumer, which takes no lock). In SRAM, where DMA reaches (RM0090
/// 2.3.1: not the core-coupled RAM).
pub type TxBuffer<const N: usize> = bbqueue::nicknames::Churrasco<N>;
/// The port's end of a [`TxBuffer`].
pub type TxProducer<const N: usize> =
    bbqueue::prod_cons::stream::StreamProducer<&'static TxBuffer<N>>;
/// The UART's end of a [`TxBuffer`].
pub type TxConsumer<const N: usize> =
    bbqueue::prod_cons::stream::StreamConsumer<&'static TxBuffer<N>>;
/// Bytes read from a [`TxBuffer`], held while a transfer sends them.
pub type TxGrant<const N: usize> = bbqueue::prod_cons::stream::StreamGrantR<&'static TxBuffer<N>>;

impl<const N: usize> TxQueue for TxProducer<N> {
    fn put<E>(
        &mut self,
        n: usize,
        write: impl FnOnce(&mut [u8]) -> Result<usize, E>,
    ) -> Option<Result<usize, E>> {
        let mut room = self.grant_exact(n).ok()?;
        let r = write(&mut room);
        // A grant dropped uncommitted queues nothing.
        if let Ok(k) = r {
            room.commit(k);
        }
        Some(r)
    }
}

impl<const N: usize> TxQueue for ByteRing<N> {
    fn put<E>(
        &mut self,
        n: usize,
        write: impl FnOnce(&mut [u8]) -> Result<usize, E>,
    ) -> Option<Result<usize, E>> {
        let r = write(self.grant(n)?);
        if let Ok(k) = r {
            self.commit(k);
        }
        Some(r)
    }
}

/// A ring of `N` bytes.
pub struct ByteRing<const N: usize> {
    buf: [u8; N],
    /// The oldest queued byte.
    head: usize,
    /// Where the next byte goes.
    tail: usize,
    /// The queued bytes wrap: they run `head..end`, then `0..tail`.
    wrapped: bool,
    /// End of the queued bytes before the wrap (`N` unless a frame
    /// skipped the last bytes).
    end: usize,
    /// The last [`ByteRing::grant`] was at the buffer's start.
    at_start: bool,
}

impl<const N: usize> Default for ByteRing<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> ByteRing<N> {
    /// An empty ring.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            head: 0,
            tail: 0,
            wrapped: false,
            end: N,
            at_start: false,
        }
    }

    /// Bytes queued.
    pub fn len(&self) -> usize {
        if self.wrapped {
            self.end - self.head + self.tail
        } else {
            self.tail - self.head
        }
    }

    /// Nothing queued.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The longest frame that fits now, in one piece.
    pub fn free(&self) -> usize {
        if self.wrapped {
            self.head - self.tail
        } else {
            (N - self.tail).max(self.head)
        }
    }

    /// At least `n` contiguous free bytes (all there are at that place):
    /// after the queued ones if they have the room before the buffer's
    /// end, else at its start; `None` if neither has. Write the frame
    /// there and [`ByteRing::commit`] it.
    pub fn grant(&mut self, n: usize) -> Option<&mut [u8]> {
        let (at, to, start) = if self.wrapped {
            (self.tail, self.head, false)
        } else if N - self.tail >= n {
            (self.tail, N, false)
        } else {
            (0, self.head, true)
        };
        if to - at < n {
            return None;
        }
        self.at_start = start;
        self.buf.get_mut(at..to)
    }

    /// Queue the first `n` bytes of the last [`ByteRing::grant`] (at most
    /// what it offered).
    pub fn commit(&mut self, n: usize) {
        if n == 0 {
            return;
        }
        if self.at_start && !self.wrapped {
            // The bytes from the tail to the buffer's end are skipped.
            self.at_start = false;
            self.end = self.tail;
            self.wrapped = true;
            self.tail = 0;
            if self.head == self.end {
                // Nothing was queued before the skip.
                (self.head, self.end, self.wrapped) = (0, N, false);
            }
        }
        let limit = if self.wrapped { self.head } else { N };
        self.tail += n.min(limit - self.tail);
    }

    /// Append all of `bytes`, in one piece, or nothing if they do not
    /// fit.
    pub fn push(&mut self, bytes: &[u8]) -> bool {
        let Some(room) = self.grant(bytes.len()) else {
            return false;
        };
        if let Some(d) = room.get_mut(..bytes.len()) {
            d.copy_from_slice(bytes);
        }
        self.commit(bytes.len());
        true
    }

    /// The oldest queued bytes that are contiguous in the ring.
    pub fn front(&self) -> &[u8] {
        let to = if self.wrapped { self.end } else { self.tail };
        self.buf.get(self.head..to).unwrap_or(&[])
    }

    /// Drop the `n` oldest bytes (at most what is queued).
    pub fn consume(&mut self, n: usize) {
        let mut n = n.min(self.len());
        if self.wrapped {
            let k = n.min(self.end - self.head);
            self.head += k;
            n -= k;
            if self.head == self.end {
                (self.head, self.end, self.wrapped) = (0, N, false);
            }
        }
        self.head += n;
        if self.head == self.tail && !self.wrapped {
            // Empty: start again at the buffer's start, where the most
            // contiguous room is.
            (self.head, self.tail) = (0, 0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::ByteRing;

    /// Against a VecDeque model, over wrap-arounds and refusals: what is
    /// queued comes out in order, skipped bytes never; a frame is refused
    /// only if it does not fit in the larger free run (at least half the
    /// free bytes).
    #[test]
    fn the_ring_matches_a_deque() {
        let mut r = ByteRing::<37>::new();
        let mut m = std::collections::VecDeque::new();
        let mut x = 1u8;
        let mut refused = 0;
        for step in 0..4000usize {
            let n = step * 7 % 23;
            let bytes: Vec<u8> = (0..n)
                .map(|_| {
                    x = x.wrapping_mul(31).wrapping_add(7);
                    x
                })
                .collect();
            let free = 37 - m.len();
            // Every other frame written in place, the rest pushed.
            let ok = if step % 2 == 0 {
                match r.grant(n) {
                    Some(room) => {
                        assert!(room.len() >= n);
                        room[..n].copy_from_slice(&bytes);
                        r.commit(n);
                        true
                    }
                    None => false,
                }
            } else {
                r.push(&bytes)
            };
            if ok {
                assert!(n <= free);
                m.extend(&bytes);
            } else {
                assert!(2 * n > free, "refused {n} with {free} free");
                refused += 1;
            }
            assert!(r.free() <= 37 - m.len());
            let take = step * 5 % 19;
            let mut got = Vec::new();
            while got.len() < take && !r.is_empty() {
                let f = r.front();
                let k = f.len().min(take - got.len());
                got.extend_from_slice(&f[..k]);
                r.consume(k);
            }
            let want: Vec<u8> = m.drain(..take.min(m.len())).collect();
            assert_eq!(got, want);
            assert_eq!(r.len(), m.len());
        }
        assert!(refused > 100, "the test must reach a full ring");
    }

    /// A frame that does not fit before the end goes to the start; the
    /// bytes it skipped are not sent.
    #[test]
    fn a_frame_that_meets_the_end_goes_whole_to_the_start() {
        let mut r = ByteRing::<10>::new();
        assert!(r.push(&[1, 2, 3, 4, 5, 6, 7, 8]));
        r.consume(5);
        // 2 free at the end, 5 at the start: 6 fits in neither.
        assert_eq!(r.free(), 5);
        assert!(!r.push(&[9; 6]));
        assert!(r.push(&[9, 10, 11]));
        assert_eq!(r.len(), 6);
        assert_eq!(r.front(), &[6, 7, 8]);
        r.consume(3);
        assert_eq!(r.front(), &[9, 10, 11]);
        r.consume(3);
        assert!(r.is_empty());
        assert!(r.push(&[0; 10]));
    }
}
