//! Where the sidecar's bytes come from, behind one trait: a stdin pipe, a
//! TCP connection to a listening sidecar, a file of recorded messages, or a
//! USB device's bulk IN endpoint (rusb against the system libusb). A TCP
//! connection and a USB device also carry the downlink back
//! ([`Source::downlink`]: the connection's other direction, the bulk OUT
//! endpoint).

use crate::Error;
use std::io::Read;
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::time::Duration;

/// A stream of bytes from the sidecar.
pub trait Source {
    /// Reads up to `buf.len()` bytes; `Ok(0)` at the end of the stream.
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error>;
    /// A short name for messages.
    fn name(&self) -> String;
    /// Where control messages to the sidecar go on this link, if it has a
    /// way back (TCP, USB); `None` for pipes and files.
    fn downlink(&self) -> Option<Result<Box<dyn std::io::Write + Send>, Error>> {
        None
    }
}

/// Any `Read` (stdin, a file, a TCP stream).
#[derive(Debug)]
pub struct Reader<R: Read> {
    inner: R,
    name: String,
    back: Option<TcpStream>,
}

impl<R: Read> Source for Reader<R> {
    fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
        loop {
            match self.inner.read(buf) {
                Ok(n) => return Ok(n),
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
                Err(source) => {
                    return Err(Error::Io {
                        what: self.name.clone(),
                        source,
                    })
                }
            }
        }
    }
    fn name(&self) -> String {
        self.name.clone()
    }
    fn downlink(&self) -> Option<Result<Box<dyn std::io::Write + Send>, Error>> {
        let s = self.back.as_ref()?;
        Some(
            s.try_clone()
                .map(|s| Box::new(s) as Box<dyn std::io::Write + Send>)
                .map_err(|source| Error::Io {
                    what: self.name.clone(),
                    source,
                }),
        )
    }
}

/// Standard input.
pub fn pipe() -> Reader<std::io::Stdin> {
    Reader {
        inner: std::io::stdin(),
        name: "pipe".into(),
        back: None,
    }
}

/// A file of recorded messages.
pub fn file(path: &Path) -> Result<Reader<std::fs::File>, Error> {
    let name = path.display().to_string();
    let f = std::fs::File::open(path).map_err(|source| Error::Io {
        what: name.clone(),
        source,
    })?;
    Ok(Reader {
        inner: f,
        name,
        back: None,
    })
}

/// Connects to a sidecar listening at `addr`, retrying for up to `wait`
/// (the sidecar may still be starting).
pub fn tcp(addr: &str, wait: Duration) -> Result<Reader<TcpStream>, Error> {
    let t0 = std::time::Instant::now();
    loop {
        match TcpStream::connect(addr) {
            Ok(s) => {
                let name = format!("tcp {addr}");
                let back = s.try_clone().map_err(|source| Error::Io {
                    what: name.clone(),
                    source,
                })?;
                return Ok(Reader {
                    inner: s,
                    name,
                    back: Some(back),
                });
            }
            Err(e) if t0.elapsed() < wait => {
                let _ = e;
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(source) => {
                return Err(Error::Io {
                    what: format!("tcp {addr}"),
                    source,
                })
            }
        }
    }
}

/// The sidecar's USB identity (see `docs/protocol.md`): a development
/// VID:PID, vendor-class interface 0, bulk IN endpoint 0x81.
pub const USB_VID: u16 = 0xc0de;
/// Product id.
pub const USB_PID: u16 = 0xcafe;
/// Interface number.
pub const USB_INTERFACE: u8 = 0;
/// Bulk IN endpoint address.
pub const USB_EP_IN: u8 = 0x81;
/// Bulk OUT endpoint address (the downlink).
pub const USB_EP_OUT: u8 = 0x01;

/// Parses `VID:PID` in hex.
pub fn parse_vid_pid(s: &str) -> Result<(u16, u16), Error> {
    let bad = || Error::BadId(s.to_string());
    let (v, p) = s.split_once(':').ok_or_else(bad)?;
    Ok((
        u16::from_str_radix(v, 16).map_err(|_| bad())?,
        u16::from_str_radix(p, 16).map_err(|_| bad())?,
    ))
}

#[cfg(feature = "usb")]
pub use usb::Usb;

/// Which source, as the CLI names it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Spec {
    /// `--usb [VID:PID]`.
    Usb(u16, u16),
    /// `--tcp ADDR`.
    Tcp(String),
    /// `--pipe`.
    Pipe,
    /// `--file PATH`.
    File(PathBuf),
}

/// Opens `spec`.
pub fn open(spec: &Spec) -> Result<Box<dyn Source>, Error> {
    Ok(match spec {
        #[cfg(feature = "usb")]
        Spec::Usb(v, p) => Box::new(Usb::open(*v, *p)?),
        #[cfg(not(feature = "usb"))]
        Spec::Usb(..) => {
            return Err(Error::Usb(
                "this build of spiv has no USB support (built without the `usb` feature)"
                    .to_string(),
            ))
        }
        Spec::Tcp(a) => Box::new(tcp(a, Duration::from_secs(10))?),
        Spec::Pipe => Box::new(pipe()),
        Spec::File(p) => Box::new(file(p)?),
    })
}

/// The USB source (the `usb` feature: rusb against the system libusb).
#[cfg(feature = "usb")]
mod usb {
    use std::time::Duration;

    use super::{Error, Source, USB_EP_IN, USB_EP_OUT, USB_INTERFACE};

    /// A sidecar on USB: bulk IN reads into buffers of whole 512-byte packets.
    pub struct Usb {
        handle: std::sync::Arc<rusb::DeviceHandle<rusb::Context>>,
        name: String,
    }

    /// The bulk OUT endpoint as a writer (the downlink on USB).
    struct UsbOut(std::sync::Arc<rusb::DeviceHandle<rusb::Context>>);

    impl std::io::Write for UsbOut {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0
                .write_bulk(USB_EP_OUT, buf, Duration::from_secs(1))
                .map_err(|e| std::io::Error::other(format!("usb bulk OUT: {e}")))
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl std::fmt::Debug for Usb {
        fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
            f.write_str(&self.name)
        }
    }

    impl Usb {
        /// Opens the first device with `vid:pid` and claims its interface.
        pub fn open(vid: u16, pid: u16) -> Result<Usb, Error> {
            use rusb::UsbContext;
            let usb = |e: rusb::Error| Error::Usb(e.to_string());
            // Never the global context: it panics when libusb cannot start.
            let ctx = rusb::Context::new().map_err(|e| {
                Error::Usb(format!(
                    "cannot initialise libusb ({e}); is USB available here?"
                ))
            })?;
            let handle = ctx.open_device_with_vid_pid(vid, pid).ok_or_else(|| {
                Error::Usb(format!(
                    "no device {vid:04x}:{pid:04x} attached (or no permission to open it)"
                ))
            })?;
            let _ = handle.set_auto_detach_kernel_driver(true);
            handle.claim_interface(USB_INTERFACE).map_err(usb)?;
            Ok(Usb {
                handle: std::sync::Arc::new(handle),
                name: format!("usb {vid:04x}:{pid:04x}"),
            })
        }
    }

    impl Source for Usb {
        fn read(&mut self, buf: &mut [u8]) -> Result<usize, Error> {
            // A multiple of the high-speed packet size, so libusb never overflows.
            let n = (buf.len() / 512 * 512).max(512).min(buf.len());
            loop {
                match self
                    .handle
                    .read_bulk(USB_EP_IN, &mut buf[..n], Duration::from_secs(1))
                {
                    Ok(k) => return Ok(k),
                    Err(rusb::Error::Timeout) => continue,
                    Err(rusb::Error::NoDevice) => return Ok(0),
                    Err(e) => return Err(Error::Usb(e.to_string())),
                }
            }
        }
        fn name(&self) -> String {
            self.name.clone()
        }
        fn downlink(&self) -> Option<Result<Box<dyn std::io::Write + Send>, Error>> {
            Some(Ok(Box::new(UsbOut(self.handle.clone()))))
        }
    }
}
