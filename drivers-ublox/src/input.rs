//! Where the receiver's bytes come from: a serial device (or any tty, such as a pseudo-terminal),
//! a TCP stream (a network receiver or `ser2net`), or a file (a log of a receiver's output).
//!
//! A serial port is opened as a plain file and put in raw mode with termios (8 data bits, no
//! parity, no flow control, no echo, no line editing, the given baud rate): no udev, no
//! system library. Reads wait in `poll` with a timeout, so that a stop request is seen within
//! [`POLL_INTERVAL_MS`] even on a silent line. A serial device or pseudo-terminal whose other
//! end goes away (`EIO`, hang-up) ends the input like the end of a file.

use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
use nix::sys::termios::{self, BaudRate, SetArg, SpecialCharacterIndices};
use std::fs::File;
use std::io::{ErrorKind, Read};
use std::net::TcpStream;
use std::os::fd::AsFd;
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// Longest wait for input before looking at the stop request, ms.
pub const POLL_INTERVAL_MS: u16 = 200;

/// Failure to open an input.
#[derive(Debug, thiserror::Error)]
pub enum OpenError {
    /// The device or file could not be opened.
    #[error("cannot open {path}: {source}")]
    Open {
        /// Path.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The serial device refused the raw mode or the baud rate.
    #[error("cannot configure {path} (termios): {source}")]
    Termios {
        /// Path.
        path: PathBuf,
        /// Why.
        source: nix::Error,
    },
    /// The baud rate is not one a serial port supports.
    #[error(
        "unsupported baud rate {0} (4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800 or 921600)"
    )]
    Baud(u32),
    /// The TCP connection could not be made.
    #[error("cannot connect to {addr}: {source}")]
    Connect {
        /// Address.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
}

/// What one read gave.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ReadOutcome {
    /// This many bytes.
    Data(usize),
    /// Nothing within the poll interval (or a signal interrupted the wait).
    Idle,
    /// The input ended (end of file, connection closed, device hung up).
    End,
}

enum Kind {
    File(File),
    Tty(File),
    Tcp(TcpStream),
}

/// An open input.
pub struct Input {
    kind: Kind,
}

fn baud(rate: u32) -> Result<BaudRate, OpenError> {
    Ok(match rate {
        4800 => BaudRate::B4800,
        9600 => BaudRate::B9600,
        19200 => BaudRate::B19200,
        38400 => BaudRate::B38400,
        57600 => BaudRate::B57600,
        115200 => BaudRate::B115200,
        230400 => BaudRate::B230400,
        460800 => BaudRate::B460800,
        921600 => BaudRate::B921600,
        other => return Err(OpenError::Baud(other)),
    })
}

impl Input {
    /// Open a serial device (or pseudo-terminal) in raw mode at `baud_rate`.
    pub fn serial(path: &Path, baud_rate: u32) -> Result<Self, OpenError> {
        let speed = baud(baud_rate)?;
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .custom_flags(nix::libc::O_NOCTTY)
            .open(path)
            .map_err(|source| OpenError::Open {
                path: path.to_path_buf(),
                source,
            })?;
        let termios_err = |source| OpenError::Termios {
            path: path.to_path_buf(),
            source,
        };
        let mut t = termios::tcgetattr(file.as_fd()).map_err(termios_err)?;
        termios::cfmakeraw(&mut t);
        termios::cfsetspeed(&mut t, speed).map_err(termios_err)?;
        t.control_flags |= termios::ControlFlags::CLOCAL | termios::ControlFlags::CREAD;
        t.control_chars[SpecialCharacterIndices::VMIN as usize] = 1;
        t.control_chars[SpecialCharacterIndices::VTIME as usize] = 0;
        termios::tcsetattr(file.as_fd(), SetArg::TCSANOW, &t).map_err(termios_err)?;
        Ok(Self {
            kind: Kind::Tty(file),
        })
    }

    /// Connect to a TCP stream.
    pub fn tcp(addr: &str) -> Result<Self, OpenError> {
        let s = TcpStream::connect(addr).map_err(|source| OpenError::Connect {
            addr: addr.to_string(),
            source,
        })?;
        Ok(Self { kind: Kind::Tcp(s) })
    }

    /// Open a file (read to its end).
    pub fn file(path: &Path) -> Result<Self, OpenError> {
        let f = File::open(path).map_err(|source| OpenError::Open {
            path: path.to_path_buf(),
            source,
        })?;
        Ok(Self {
            kind: Kind::File(f),
        })
    }

    /// Read what is available into `buf`, waiting at most [`POLL_INTERVAL_MS`].
    pub fn read(&mut self, buf: &mut [u8]) -> std::io::Result<ReadOutcome> {
        let ready = {
            let fd = match &self.kind {
                Kind::File(f) | Kind::Tty(f) => f.as_fd(),
                Kind::Tcp(s) => s.as_fd(),
            };
            let mut fds = [PollFd::new(fd, PollFlags::POLLIN)];
            match poll(&mut fds, PollTimeout::from(POLL_INTERVAL_MS)) {
                Ok(0) => return Ok(ReadOutcome::Idle),
                Ok(_) => true,
                Err(nix::Error::EINTR) => return Ok(ReadOutcome::Idle),
                Err(e) => return Err(e.into()),
            }
        };
        debug_assert!(ready);
        let r = match &mut self.kind {
            Kind::File(f) | Kind::Tty(f) => f.read(buf),
            Kind::Tcp(s) => s.read(buf),
        };
        match r {
            Ok(0) => Ok(ReadOutcome::End),
            Ok(n) => Ok(ReadOutcome::Data(n)),
            Err(e) if e.kind() == ErrorKind::Interrupted || e.kind() == ErrorKind::WouldBlock => {
                Ok(ReadOutcome::Idle)
            }
            // The other end of a tty went away (pseudo-terminal master closed, USB unplugged).
            Err(e)
                if matches!(self.kind, Kind::Tty(_))
                    && e.raw_os_error() == Some(nix::libc::EIO) =>
            {
                Ok(ReadOutcome::End)
            }
            Err(e) => Err(e),
        }
    }
}
