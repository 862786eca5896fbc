//! The OPC UA server's PKI directory kept private: async-opcua 0.19 writes the server's
//! key `private/private.pem` with the process's umask (0644 under the usual 022) and has no
//! option for its mode. So the private directory is made 0700 before the crate writes the
//! key into it, and the key is set to 0600 once it exists; a directory or key found open
//! to others at start is repaired, with a warning naming the file.

use std::os::unix::fs::{DirBuilderExt, PermissionsExt};
use std::path::{Path, PathBuf};

use anyhow::Context;

/// The server's key, relative to the PKI directory (the builder's `private_key_path`).
pub const PRIVATE_KEY: &str = "private/private.pem";
/// Mode of the directory holding the key.
const PRIVATE_DIR_MODE: u32 = 0o700;
/// Mode of the key.
const PRIVATE_KEY_MODE: u32 = 0o600;

/// The private directory under `pki_dir`.
fn private_dir(pki_dir: &Path) -> PathBuf {
    pki_dir.join(PRIVATE_KEY).parent().map_or_else(|| pki_dir.to_path_buf(), Path::to_path_buf)
}

/// `path` set to `mode` when it has any bit `mode` lacks; `true` when it was repaired.
fn restrict(path: &Path, mode: u32) -> anyhow::Result<bool> {
    let meta = std::fs::metadata(path).with_context(|| format!("{}: cannot read its mode", path.display()))?;
    let now = meta.permissions().mode() & 0o777;
    if now & !mode == 0 {
        return Ok(false);
    }
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).with_context(|| {
        format!("{}: mode {now:04o} is open to others and cannot be set to {mode:04o}", path.display())
    })?;
    Ok(true)
}

/// Before the server is built: the private directory exists with mode 0700, and a key
/// already there is 0600 (each repaired with a warning when found open).
pub fn prepare(pki_dir: &Path) -> anyhow::Result<()> {
    let dir = private_dir(pki_dir);
    if !dir.is_dir() {
        std::fs::DirBuilder::new()
            .recursive(true)
            .mode(PRIVATE_DIR_MODE)
            .create(&dir)
            .with_context(|| format!("opcua.pki_dir: cannot make {}", dir.display()))?;
    }
    if restrict(&dir, PRIVATE_DIR_MODE)? {
        tracing::warn!(dir = %dir.display(), "OPC UA private directory was open to others: set to 0700");
    }
    secure_key(pki_dir)
}

/// After the server is built (which writes a new key): the key is 0600.
pub fn secure_key(pki_dir: &Path) -> anyhow::Result<()> {
    let key = pki_dir.join(PRIVATE_KEY);
    if key.exists() && restrict(&key, PRIVATE_KEY_MODE)? {
        tracing::warn!(key = %key.display(), "OPC UA private key was open to others: set to 0600");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mode(p: &Path) -> u32 {
        std::fs::metadata(p).expect("exists").permissions().mode() & 0o777
    }

    #[test]
    fn the_private_directory_and_key_are_made_and_repaired_private() {
        let dir = tempfile::tempdir().expect("temp dir");
        let pki = dir.path().join("pki");
        prepare(&pki).expect("prepared");
        assert_eq!(mode(&pki.join("private")), 0o700);
        // The crate writes the key with the umask's mode; an operator opened the directory.
        let key = pki.join(PRIVATE_KEY);
        std::fs::write(&key, "-----BEGIN PRIVATE KEY-----\n").expect("write");
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o644)).expect("chmod");
        secure_key(&pki).expect("secured");
        assert_eq!(mode(&key), 0o600);
        std::fs::set_permissions(pki.join("private"), std::fs::Permissions::from_mode(0o755)).expect("chmod");
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o640)).expect("chmod");
        prepare(&pki).expect("repaired");
        assert_eq!((mode(&pki.join("private")), mode(&key)), (0o700, 0o600));
        // A stricter key (0400) is left as it is.
        std::fs::set_permissions(&key, std::fs::Permissions::from_mode(0o400)).expect("chmod");
        secure_key(&pki).expect("secured");
        assert_eq!(mode(&key), 0o400);
    }
}
