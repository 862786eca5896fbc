//! The HTTP server's token (issue 19, security): `forgemon run` with `[http] token_file` on
//! a loopback listener (the parser accepts a token there too) refuses every request without
//! `Authorization: Bearer <token>` with 401, `/status`, `/metrics`, `/ack`, `/billet` and the
//! dashboard alike, and serves them with it; a `GET` may carry the token as `?token=` (the
//! page and its event stream, which a browser's EventSource opens without headers), a `POST`
//! may not. A token file that cannot be read stops the service with an error naming it.
//!
//! Issue 39: the scheme is matched without regard to case (RFC 7235), and a token file that
//! group or others may read, or a token shorter than 16 characters, stops the service with
//! an error naming the file and the fix.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

use common::{free_port, service_toml, spawn_service, write_private};

const TOKEN: &str = "9f2c-forge-7a1e-5b0d";

/// The status code, headers and body of one request on loopback (`auth`: the Authorization
/// header's value).
fn request(port: u16, method: &str, path: &str, auth: Option<&str>) -> (u16, String, String) {
    let mut s = TcpStream::connect(("127.0.0.1", port)).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(2))).unwrap();
    let auth = auth.map(|a| format!("authorization: {a}\r\n")).unwrap_or_default();
    write!(s, "{method} {path} HTTP/1.1\r\nhost: localhost\r\n{auth}content-length: 0\r\nconnection: close\r\n\r\n")
        .unwrap();
    let mut out = Vec::new();
    // An event stream never ends: what arrived before the timeout is enough.
    let _ = s.read_to_end(&mut out);
    let out = String::from_utf8_lossy(&out).to_string();
    let (head, body) = out.split_once("\r\n\r\n").unwrap_or((&out, ""));
    let code = head.split_whitespace().nth(1).and_then(|c| c.parse().ok()).unwrap_or(0);
    (code, head.to_lowercase(), body.to_string())
}

fn config(dir: &Path, http: u16) -> std::path::PathBuf {
    service_toml(dir, http, "token_file = \"token\"", "")
}

#[test]
fn every_endpoint_needs_the_token_and_serves_with_it() {
    let dir = tempfile::tempdir().unwrap();
    write_private(&dir.path().join("token"), &format!("{TOKEN}\n"));
    let http = free_port();
    let mut child = spawn_service(&config(dir.path(), http), http);
    let bearer = format!("Bearer {TOKEN}");
    let ok = Some(bearer.as_str());
    let q = format!("?token={TOKEN}");

    for (method, path) in [
        ("GET", "/status"),
        ("GET", "/metrics"),
        ("GET", "/"),
        ("GET", "/dashboard/state"),
        ("GET", "/events"),
        ("POST", "/ack"),
        ("POST", "/billet"),
    ] {
        for wrong in [None, Some("Bearer 9f2c-forge-7a1e-5b0e"), Some(TOKEN), Some("Basic OWYyYw==")] {
            let (code, head, _) = request(http, method, path, wrong);
            assert_eq!(code, 401, "{method} {path} with {wrong:?}");
            assert!(head.contains("www-authenticate: bearer"), "{head}");
        }
        // RFC 7235 §2.1: the scheme is case-insensitive (the POSTs are sent with it below).
        for scheme in ["bearer", "BEARER", "bEaReR"].iter().filter(|_| method == "GET") {
            let (code, _, _) = request(http, method, path, Some(&format!("{scheme} {TOKEN}")));
            assert_ne!(code, 401, "{method} {path} with the scheme {scheme}");
        }
    }
    // A POST cannot carry the token in its query: a link cannot acknowledge.
    assert_eq!(request(http, "POST", &format!("/ack{q}"), None).0, 401);
    assert_eq!(request(http, "POST", &format!("/billet{q}"), None).0, 401);
    assert_eq!(request(http, "GET", "/status?token=9f2c", None).0, 401);

    let (code, _, body) = request(http, "GET", "/status", ok);
    assert_eq!(code, 200);
    let status: serde_json::Value = serde_json::from_str(&body).unwrap();
    assert_eq!(status["machine"], "hammer");
    assert_eq!(status["billets"], 0);
    assert!(request(http, "GET", "/metrics", ok).2.contains("forgemon_blows_total 0"));
    let (code, _, page) = request(http, "GET", &format!("/{q}"), None);
    assert_eq!(code, 200);
    assert!(page.contains("<title>forgemon</title>"));
    let (code, head, _) = request(http, "GET", &format!("/events{q}"), None);
    assert_eq!(code, 200);
    assert!(head.contains("content-type: text/event-stream"), "{head}");
    // Nothing latched yet: the acknowledgement is accepted and changes nothing.
    assert_eq!(request(http, "POST", "/ack", Some(&format!("bearer {TOKEN}"))).0, 202);
    assert_eq!(request(http, "POST", "/billet", Some(&format!("BEARER {TOKEN}"))).0, 202);
    // The accepted billet signal reached the service: a billet started.
    let deadline = std::time::Instant::now() + Duration::from_secs(5);
    loop {
        let status: serde_json::Value = serde_json::from_str(&request(http, "GET", "/status", ok).2).unwrap();
        if status["billets"] == 1 {
            break;
        }
        assert!(std::time::Instant::now() < deadline, "POST /billet did not start a billet: {status}");
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = child.kill();
    let _ = child.wait();
}

#[test]
fn an_unreadable_or_empty_token_file_stops_the_service_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let http = free_port();
    let cfg = config(dir.path(), http);
    let token = dir.path().join("token");
    for content in [None, Some(" \n")] {
        if let Some(c) = content {
            write_private(&token, c);
        }
        let out = Command::new(env!("CARGO_BIN_EXE_forgemon"))
            .args(["run", "--config", cfg.to_str().unwrap()])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success());
        assert!(stderr.contains(&token.display().to_string()), "{stderr}");
        assert!(stderr.contains(if content.is_some() { "is empty" } else { "cannot read" }), "{stderr}");
    }
}

/// The stderr of `forgemon run` with `token_file` holding `text` with `mode`; it must fail.
fn refused_start(text: &str, mode: u32) -> (String, std::path::PathBuf) {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().unwrap();
    let http = free_port();
    let cfg = config(dir.path(), http);
    let token = dir.path().join("token");
    std::fs::write(&token, text).unwrap();
    std::fs::set_permissions(&token, std::fs::Permissions::from_mode(mode)).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_forgemon"))
        .args(["run", "--config", cfg.to_str().unwrap()])
        .stdout(std::process::Stdio::null())
        .output()
        .unwrap();
    assert!(!out.status.success(), "the service started with a token file of mode {mode:o}");
    (String::from_utf8_lossy(&out.stderr).to_string(), token)
}

/// Issue 39: a token file readable by group or others (0644, 0666) was taken with no word.
#[test]
fn a_token_file_group_or_others_may_read_stops_the_service_with_the_chmod_that_fixes_it() {
    for mode in [0o644, 0o666, 0o640] {
        let (stderr, token) = refused_start(&format!("{TOKEN}\n"), mode);
        assert!(stderr.contains(&format!("chmod 600 {}", token.display())), "{mode:o}: {stderr}");
    }
}

/// Issue 39: a 1-character token was taken with no word.
#[test]
fn a_short_token_stops_the_service_naming_the_minimum() {
    let (stderr, token) = refused_start("x\n", 0o600);
    assert!(stderr.contains(&token.display().to_string()), "{stderr}");
    assert!(stderr.contains("1 characters, at least 16"), "{stderr}");
}
