//! Secret files (the OPC UA password, tokens) read the way ssh reads its keys: a file that
//! its group or other users may read or write is refused, and the error says the fix
//! (`chmod 600 FILE`). A secret that others can read is no secret, and a service that
//! takes one silently teaches its operators that this is fine.

use std::os::unix::fs::PermissionsExt;
use std::path::Path;

use anyhow::Context;

/// Permission bits a secret file must not have: any for the group or others.
const OPEN_TO_OTHERS: u32 = 0o077;

/// The text of the secret file `path`, named `what` in errors (`[opcua] password_file`),
/// without its trailing newline. Refused when it is open to group or others, or empty.
pub fn read(path: &Path, what: &str) -> anyhow::Result<String> {
    let meta = std::fs::metadata(path).with_context(|| format!("{}: cannot read {what}", path.display()))?;
    let mode = meta.permissions().mode() & 0o777;
    if mode & OPEN_TO_OTHERS != 0 {
        anyhow::bail!(
            "{}: {what} is open to its group or others (mode {mode:04o}); a secret must be readable by the \
             service's user alone: run `chmod 600 {}`",
            path.display(),
            path.display()
        );
    }
    let text = std::fs::read_to_string(path).with_context(|| format!("{}: cannot read {what}", path.display()))?;
    let secret = text.trim_end_matches(['\r', '\n']);
    if secret.is_empty() {
        anyhow::bail!("{}: {what} is empty", path.display());
    }
    Ok(secret.to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(path: &Path, text: &str, mode: u32) {
        std::fs::write(path, text).expect("write");
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).expect("chmod");
    }

    #[test]
    fn a_file_open_to_others_is_refused_with_the_fix() {
        let dir = tempfile::tempdir().expect("temp dir");
        let p = dir.path().join("pass");
        for mode in [0o644, 0o640, 0o604, 0o666, 0o620] {
            write(&p, "s3cret\n", mode);
            let e = read(&p, "[opcua] password_file").expect_err("refused").to_string();
            assert!(e.contains(&format!("chmod 600 {}", p.display())), "{mode:o}: {e}");
            assert!(e.contains(&format!("{mode:04o}")) && e.contains("[opcua] password_file"), "{e}");
        }
        for mode in [0o600, 0o400] {
            write(&p, "s3cret\r\n", mode);
            assert_eq!(read(&p, "x").expect("taken"), "s3cret", "{mode:o}");
        }
        write(&p, "\n", 0o600);
        assert!(read(&p, "x").expect_err("empty").to_string().contains("empty"));
        assert!(read(&dir.path().join("none"), "x").expect_err("missing").to_string().contains("none"));
    }
}
