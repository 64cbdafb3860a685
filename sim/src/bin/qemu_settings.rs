//! Saved settings survive a reset, end to end in QEMU (`mps2-an386`):
//! the link's commands go through the board's own path (`app::receive`,
//! the port, `app::store`, the settings store) to a flash that keeps its
//! cells across a system reset. QEMU models no flash controller for either
//! of its boards, so the store's flash is the emulated NOR flash
//! (`gyro_sim::flash::NorSim`, the STM32F4's programming rules) over the
//! `STORE` region of memory.x, which on this machine is RAM outside the
//! image: QEMU restores the image at a reset and leaves the rest.
//!
//! 1. Cold boot (RAM zeroed: no record). Set divider 7 and method Zhang,
//!    save; the save is acknowledged once read back. Reset.
//! 2. The saved settings come up, the status frame says `Stored`. Factory
//!    reset; acknowledged. Reset.
//! 3. The defaults come up, `Defaults`. Pass.
//!
//! Anything else fails the run.
#![no_std]
#![no_main]
#![allow(unsafe_code)]

use cortex_m_rt::entry;
use defmt_semihosting as _;
use embedded_hal_nb::nb;
use rtic_core::Exclusive;

use gyro_array::algo::fusion::{AdaptiveConfig, Method};
use gyro_array::app;
use gyro_array::link::msg::{Ack, Command, Frame, FusionMethod, Op, Reject, Settings, StoreState};
use gyro_array::link::port::RingPort;
use gyro_array::link::wire::{encode, Decoder, MAX_FRAME};
use gyro_array::pipeline::{Pipeline, PipelineConfig};
use gyro_array::store::Store;
use gyro_sim::flash::NorSim;
use gyro_sim::qemu::{self, exit};

/// This binary's guard for its stage word (`gyro_sim::qemu::stage`).
const GUARD: u32 = 0x5E77_1000;

fn stage() -> u32 {
    qemu::stage(GUARD)
}

fn set_stage(s: u32) {
    qemu::set_stage(GUARD, s)
}

/// The STORE region (memory.x), 2 × 128 KiB.
fn store_cells() -> &'static mut [u8] {
    unsafe extern "C" {
        static mut _store_start: u8;
        static mut _store_end: u8;
    }
    let start = &raw mut _store_start;
    let len = (&raw mut _store_end as usize) - (start as usize);
    // SAFETY: the region is RAM on this machine that nothing else in the
    // image refers to; called once.
    unsafe { core::slice::from_raw_parts_mut(start, len) }
}

const SECTOR: usize = 128 * 1024;

/// Commands as the controller sends them, one after the other.
struct Bytes<'a>(&'a [u8]);

impl embedded_hal_nb::serial::ErrorType for Bytes<'_> {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Read<u8> for Bytes<'_> {
    fn read(&mut self) -> nb::Result<u8, Self::Error> {
        let (&b, rest) = self.0.split_first().ok_or(nb::Error::WouldBlock)?;
        self.0 = rest;
        Ok(b)
    }
}

/// What the port sent.
struct Sent {
    buf: [u8; 2048],
    len: usize,
}

impl embedded_hal_nb::serial::ErrorType for Sent {
    type Error = core::convert::Infallible;
}

impl embedded_hal_nb::serial::Write<u8> for Sent {
    fn write(&mut self, b: u8) -> nb::Result<(), Self::Error> {
        let slot = self.buf.get_mut(self.len).ok_or(nb::Error::WouldBlock)?;
        *slot = b;
        self.len += 1;
        Ok(())
    }
    fn flush(&mut self) -> nb::Result<(), Self::Error> {
        Ok(())
    }
}

/// Send `ops` to the board's command path with a store over `flash`, and
/// return the store's state and whether every command was acknowledged
/// `Ok`, in order.
fn exchange(
    store: &mut Store<NorSim<'static, SECTOR>>,
    settings: Settings,
    state: StoreState,
    ops: &[Op],
) -> (Settings, bool) {
    let Ok(mut pipe) = Pipeline::<4>::new(
        PipelineConfig::default(),
        Method::Adaptive(AdaptiveConfig::default()),
    ) else {
        exit(false)
    };
    if pipe.set_method(settings.method.method()).is_err() {
        exit(false);
    }
    let mut port = RingPort::<1024>::new(settings, gyro_array::app::BOARD_FRAME_PATH);
    port.set_store_state(state);
    let mut bytes = [0u8; 4 * MAX_FRAME];
    let mut n = 0;
    for (i, &op) in ops.iter().enumerate() {
        let Some(Ok(k)) = bytes
            .get_mut(n..)
            .map(|rest| encode(i as u32, &Command { id: i as u8, op }, rest))
        else {
            exit(false)
        };
        n += k;
    }
    let mut rx = Bytes(bytes.get(..n).unwrap_or(&[]));
    let mut pipe = Exclusive(&mut pipe);
    let mut link = Exclusive(&mut port);
    while !rx.0.is_empty() {
        app::receive(&mut rx, &mut pipe, &mut link);
        app::store(store, None, &mut link);
    }
    let mut sent = Sent {
        buf: [0; 2048],
        len: 0,
    };
    port.drain(&mut sent);
    let mut dec = Decoder::<MAX_FRAME>::new();
    let mut acks = 0;
    let mut all_ok = true;
    for &b in sent.buf.get(..sent.len).unwrap_or(&[]) {
        if let Some(r) = dec.feed::<Frame>(b) {
            match r {
                Ok(d) => match d.body {
                    Frame::Ack(Ack { id, result }) => {
                        let ok = id == Some(acks) && result.is_ok();
                        if !ok {
                            let why = result.err().unwrap_or(Reject::Malformed);
                            defmt::error!("command {}: {}", id, why);
                        }
                        all_ok &= ok;
                        acks += 1;
                    }
                    _ => all_ok = false,
                },
                Err(_) => all_ok = false,
            }
        }
    }
    (port.settings(), all_ok && usize::from(acks) == ops.len())
}

#[entry]
fn main() -> ! {
    let flash = NorSim::<SECTOR>::new(store_cells(), 1);
    let Some(mut store) = Store::new(flash, 0..2 * SECTOR as u32) else {
        exit(false)
    };
    let loaded = store.load();
    let chosen = Settings {
        divider: 7,
        method: FusionMethod::Zhang,
        ..Settings::default()
    };
    match stage() {
        0 => {
            defmt::info!("stage 1: cold boot, store {}", loaded.state);
            if loaded.state == StoreState::Stored || loaded.settings != Settings::default() {
                exit(false);
            }
            let ops = [
                Op::SetDivider(7),
                Op::SetMethod(FusionMethod::Zhang),
                Op::SaveSettings,
            ];
            let (now, ok) = exchange(&mut store, loaded.settings, loaded.state, &ops);
            defmt::info!("divider 7, method Zhang, saved: acknowledged {}", ok);
            if !ok || now != chosen || store.state() != StoreState::Stored {
                exit(false);
            }
            set_stage(1);
            cortex_m::peripheral::SCB::sys_reset();
        }
        1 => {
            defmt::info!(
                "stage 2: after a reset, store {}, divider {}, method {}",
                loaded.state,
                loaded.settings.divider,
                loaded.settings.method
            );
            if loaded.state != StoreState::Stored || loaded.settings != chosen {
                exit(false);
            }
            let (now, ok) = exchange(
                &mut store,
                loaded.settings,
                loaded.state,
                &[Op::FactoryReset],
            );
            defmt::info!("factory reset: acknowledged {}", ok);
            if !ok || now != Settings::default() || store.state() != StoreState::Defaults {
                exit(false);
            }
            set_stage(2);
            cortex_m::peripheral::SCB::sys_reset();
        }
        2 => {
            defmt::info!(
                "stage 3: after a factory reset and a reset, store {}, divider {}",
                loaded.state,
                loaded.settings.divider
            );
            set_stage(0);
            let pass =
                loaded.state == StoreState::Defaults && loaded.settings == Settings::default();
            if pass {
                defmt::info!(
                    "settings: saved through the link, kept across a reset, cleared by a factory reset"
                );
            }
            exit(pass);
        }
        s => {
            defmt::error!("stage {}: unknown", s);
            set_stage(0);
            exit(false)
        }
    }
}
