//! Which device a serial path names, so that a reopen reads the same device (issue 40: after
//! a simulated device exited, the service reopened its pty path once the system had handed
//! it to another process, and read that process's data).
//!
//! The rule, as `[[sources]] path` documents it:
//! - At the first open the driver remembers the device: its number (`st_rdev`) and, for a
//!   pty, when its node was made (a pty that closes and is allocated again at the same
//!   number is another pair, another process's; devpts makes a new node for it).
//! - A path under `/dev/serial/by-id/` is udev's name for one adapter (vendor, product,
//!   serial number): it is reopened whatever device it leads to, so a USB adapter that is
//!   plugged in again, and comes back as another `ttyUSBn`, is followed.
//! - Any other path is reopened only while it is the same device: the same number, and for
//!   a pty the same node. Another one is refused (the source stays "reconnecting", with
//!   the reason, and it is logged), and the driver keeps trying for the first one.
//!   A `/dev/ttyUSBn` path that another adapter takes over has the same number, which this
//!   cannot tell: a plant configures the by-id path.

use std::fmt;
use std::os::unix::fs::MetadataExt;

/// udev's stable names of serial adapters, by vendor, product and serial number.
pub const BY_ID_DIR: &str = "/dev/serial/by-id/";

/// Unix98 pty slaves' major numbers (Linux, Documentation/admin-guide/devices.txt: 136–143).
const PTY_SLAVE_MAJORS: std::ops::RangeInclusive<u32> = 136..=143;

/// The device a path led to when it was opened.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DeviceId {
    /// The device number, `st_rdev`.
    pub rdev: u64,
    /// A pty's node's change time, ns since the epoch: the pty's allocation (`None` for any
    /// other device).
    pub pty_made_ns: Option<i64>,
}

impl DeviceId {
    /// The device at `path` now (following symlinks).
    pub fn of(path: &str) -> std::io::Result<DeviceId> {
        let m = std::fs::metadata(path)?;
        let rdev = m.rdev();
        let pty = PTY_SLAVE_MAJORS.contains(&rustix::fs::major(rdev));
        let made_ns = m.ctime().saturating_mul(1_000_000_000).saturating_add(m.ctime_nsec());
        Ok(DeviceId { rdev, pty_made_ns: pty.then_some(made_ns) })
    }
}

impl fmt::Display for DeviceId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kind = if self.pty_made_ns.is_some() { "pty" } else { "device" };
        write!(f, "{kind} {}:{}", rustix::fs::major(self.rdev), rustix::fs::minor(self.rdev))
    }
}

/// A path that leads to another device than it did at the first open (the message leaves
/// the path to the caller, who names it).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "{what} is there now, not the device first opened there ({was}): refused, waiting for that one to come back \
     (a /dev/serial/by-id/ path follows an adapter that is plugged in again)"
)]
pub struct DeviceChanged {
    pub path: String,
    pub was: DeviceId,
    pub now: DeviceId,
    what: String,
}

/// One configured path and the device it first opened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DeviceGuard {
    path: String,
    first: Option<DeviceId>,
}

impl DeviceGuard {
    pub fn new(path: impl Into<String>) -> Self {
        DeviceGuard { path: path.into(), first: None }
    }

    /// Whether `path` is a stable name of one adapter (`BY_ID_DIR`).
    pub fn is_stable(path: &str) -> bool {
        path.starts_with(BY_ID_DIR)
    }

    /// Whether the path may be opened while it leads to `now` (the module's rule).
    pub fn admit(&self, now: DeviceId) -> Result<(), DeviceChanged> {
        let Some(was) = self.first else { return Ok(()) };
        if now == was || Self::is_stable(&self.path) {
            return Ok(());
        }
        let what = if now.rdev == was.rdev { format!("a new {now} (allocated again)") } else { now.to_string() };
        Err(DeviceChanged { path: self.path.clone(), was, now, what })
    }

    /// The path opened `id`; the first one is remembered.
    pub fn opened(&mut self, id: DeviceId) {
        self.first.get_or_insert(id);
    }

    /// Open the path with `open` while it leads to a device the rule admits (else the
    /// error is `DeviceChanged`); the first device opened is remembered. The serial source
    /// and a Modbus RTU source open their ports through it.
    pub fn open<T>(&mut self, open: impl FnOnce(&str) -> std::io::Result<T>) -> std::io::Result<T> {
        let id = DeviceId::of(&self.path)?;
        self.admit(id).map_err(std::io::Error::other)?;
        let port = open(&self.path)?;
        self.opened(id);
        Ok(port)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio_serial::SerialPort;

    /// `major:minor` as glibc's `makedev` packs them (what `st_rdev` holds).
    fn dev(major: u32, minor: u32) -> u64 {
        rustix::fs::makedev(major, minor)
    }

    const USB0: DeviceId = DeviceId { rdev: 0, pty_made_ns: None };

    #[test]
    fn a_plain_path_is_reopened_only_on_the_same_device() {
        let usb0 = DeviceId { rdev: dev(188, 0), ..USB0 };
        let mut g = DeviceGuard::new("/dev/ttyUSB0");
        assert_eq!(g.admit(usb0), Ok(()));
        g.opened(usb0);
        // The adapter plugged in again as ttyUSB0: the same number.
        assert_eq!(g.admit(usb0), Ok(()));
        // Something else at the path: refused, and the first device is still the one wanted.
        let acm0 = DeviceId { rdev: dev(166, 0), ..USB0 };
        let e = g.admit(acm0).unwrap_err().to_string();
        assert!(
            e.starts_with("device 166:0 is there now, not the device first opened there (device 188:0): refused"),
            "{e}"
        );
        g.opened(usb0);
        assert_eq!(g.admit(usb0), Ok(()));
    }

    #[test]
    fn a_pty_allocated_again_at_the_same_number_is_another_device() {
        let first = DeviceId { rdev: dev(136, 5), pty_made_ns: Some(1_000) };
        let mut g = DeviceGuard::new("/dev/pts/5");
        g.opened(first);
        assert_eq!(g.admit(first), Ok(()));
        let again = DeviceId { pty_made_ns: Some(2_000), ..first };
        let e = g.admit(again).unwrap_err().to_string();
        assert!(e.starts_with("a new pty 136:5 (allocated again) is there now"), "{e}");
    }

    #[test]
    fn a_by_id_path_follows_its_adapter_to_another_tty() {
        let path = "/dev/serial/by-id/usb-FTDI_FT232R_USB_UART_A50285BI-if00-port0";
        let mut g = DeviceGuard::new(path);
        g.opened(DeviceId { rdev: dev(188, 0), ..USB0 });
        assert_eq!(g.admit(DeviceId { rdev: dev(188, 1), ..USB0 }), Ok(()));
        assert!(DeviceGuard::is_stable(path) && !DeviceGuard::is_stable("/dev/ttyUSB0"));
    }

    #[tokio::test]
    async fn a_real_pty_is_known_as_a_pty_and_reads_the_same_twice() {
        let (_master, slave) = tokio_serial::SerialStream::pair().expect("a pty pair");
        let path = slave.name().expect("the slave's path");
        let id = DeviceId::of(&path).unwrap();
        assert!(id.pty_made_ns.is_some(), "{path}: {id}");
        assert_eq!(DeviceId::of(&path).unwrap(), id, "the same pty reads the same");
    }
}
