//! Where link bytes come from: a serial port, QEMU's `-serial` back ends
//! (a TCP or Unix socket, a pipe or a file), or standard input.

use std::io::{self, Read, Write};
use std::path::PathBuf;
use std::str::FromStr;
use std::time::{Duration, Instant};

use gyro_array::link::BAUD;

/// A byte source, written `serial:PATH[@BAUD]`, `tcp:HOST:PORT`,
/// `unix:PATH`, `file:PATH` or `-` (standard input).
#[derive(Clone, Debug)]
pub enum Source {
    /// A serial port (default baud: the link's).
    Serial { path: String, baud: u32 },
    /// A TCP socket (QEMU `-serial tcp:…,server`).
    Tcp(String),
    /// A Unix socket (QEMU `-chardev socket,path=…,server=on`).
    Unix(PathBuf),
    /// A file or named pipe (QEMU `-serial file:…` or `pipe:…`).
    File(PathBuf),
    /// Standard input.
    Stdin,
}

impl FromStr for Source {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        if s == "-" {
            return Ok(Source::Stdin);
        }
        let (kind, rest) = s.split_once(':').ok_or_else(|| {
            format!("{s:?}: expected serial:PATH[@BAUD], tcp:HOST:PORT, unix:PATH, file:PATH or -")
        })?;
        if rest.is_empty() {
            return Err(format!("{s:?}: empty address"));
        }
        match kind {
            "serial" => {
                let (path, baud) = match rest.rsplit_once('@') {
                    Some((p, b)) => (
                        p,
                        b.parse::<u32>()
                            .ok()
                            .filter(|&b| b > 0)
                            .ok_or_else(|| format!("{b:?}: baud must be a positive integer"))?,
                    ),
                    None => (rest, BAUD),
                };
                Ok(Source::Serial {
                    path: path.to_string(),
                    baud,
                })
            }
            "tcp" => Ok(Source::Tcp(rest.to_string())),
            "unix" => Ok(Source::Unix(rest.into())),
            "file" => Ok(Source::File(rest.into())),
            _ => Err(format!("{kind:?}: unknown source kind")),
        }
    }
}

/// An open source: bytes in, and (sockets and serial ports) a way back
/// for commands.
pub struct Conn {
    pub reader: Box<dyn Read + Send>,
    pub writer: Option<Box<dyn Write + Send>>,
}

/// Open `src`; sockets are retried for up to `wait` (QEMU creates its
/// socket as it starts).
pub fn open(src: &Source, wait: Duration) -> io::Result<Conn> {
    let t0 = Instant::now();
    let retry = |e: io::Error| -> io::Result<()> {
        if t0.elapsed() >= wait {
            Err(e)
        } else {
            std::thread::sleep(Duration::from_millis(50));
            Ok(())
        }
    };
    match src {
        Source::Serial { path, baud } => {
            let port = serialport::new(path, *baud)
                .timeout(Duration::from_millis(200))
                .open()
                .map_err(io::Error::other)?;
            let w = port.try_clone().map_err(io::Error::other)?;
            Ok(Conn {
                reader: Box::new(TimeoutIsEmpty(port)),
                writer: Some(Box::new(w)),
            })
        }
        Source::Tcp(addr) => socket(
            || std::net::TcpStream::connect(addr),
            std::net::TcpStream::try_clone,
            retry,
        ),
        #[cfg(unix)]
        Source::Unix(path) => socket(
            || std::os::unix::net::UnixStream::connect(path),
            std::os::unix::net::UnixStream::try_clone,
            retry,
        ),
        #[cfg(not(unix))]
        Source::Unix(_) => Err(io::Error::other("Unix sockets need a Unix host")),
        Source::File(path) => Ok(Conn {
            reader: Box::new(std::fs::File::open(path)?),
            writer: None,
        }),
        Source::Stdin => Ok(Conn {
            reader: Box::new(io::stdin()),
            writer: None,
        }),
    }
}

/// Connect a socket, asking `retry` after each failure whether to go on;
/// its second handle carries the commands.
fn socket<S: Read + Write + Send + 'static>(
    connect: impl Fn() -> io::Result<S>,
    clone: impl Fn(&S) -> io::Result<S>,
    retry: impl Fn(io::Error) -> io::Result<()>,
) -> io::Result<Conn> {
    loop {
        match connect() {
            Ok(s) => {
                let w = clone(&s)?;
                return Ok(Conn {
                    reader: Box::new(s),
                    writer: Some(Box::new(w)),
                });
            }
            Err(e) => retry(e)?,
        }
    }
}

/// A serial port whose read timeout means "nothing yet", not an error.
struct TimeoutIsEmpty(Box<dyn serialport::SerialPort>);

impl Read for TimeoutIsEmpty {
    fn read(&mut self, buf: &mut [u8]) -> io::Result<usize> {
        match self.0.read(buf) {
            Err(e) if e.kind() == io::ErrorKind::TimedOut => Err(io::ErrorKind::Interrupted.into()),
            r => r,
        }
    }
}
