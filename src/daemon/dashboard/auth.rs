//! The HTTP server's bearer token (issue 19, security): when `[http] token_file` is set, every
//! request (`/status`, `/metrics`, `/billet`, the dashboard and its endpoints, `POST /ack`)
//! needs `Authorization: Bearer <token>`, the token being the file's trimmed content, read
//! once when the service starts. A browser's `EventSource` cannot send headers, so a `GET`
//! (the page, its state and its event stream) may carry the token as `?token=` instead; a
//! `POST` (`/ack`, `/billet`) needs the header, which the page's script sends, so no link or
//! foreign page can acknowledge or start a billet. Tokens are compared in constant time.
//!
//! The file is checked as ssh checks a private key (issue 39): one that group or others may
//! read or write is refused at start with the `chmod 600` that fixes it, and a token shorter
//! than [`MIN_TOKEN_CHARS`] is refused. The scheme is matched without regard to case
//! (RFC 7235 §2.1: `bearer`, `BEARER`).

use std::os::unix::fs::PermissionsExt as _;
use std::path::Path;
use std::sync::Arc;

use anyhow::Context as _;
use axum::extract::{Query, Request, State};
use axum::http::{HeaderMap, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use subtle::ConstantTimeEq as _;

use crate::daemon::slots::Admission;

/// The query parameter that carries the token on a `GET`.
pub const TOKEN_QUERY: &str = "token";
/// The shortest token accepted: 16 characters (64 bits as hex, more as random text).
pub const MIN_TOKEN_CHARS: usize = 16;
/// The permission bits of group and others; the token file must have none of them.
const GROUP_OTHER_MODE: u32 = 0o077;

/// The secret every request must present.
#[derive(Clone)]
pub struct Token(Arc<str>);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(..)")
    }
}

impl Token {
    /// The token in `file` (its trimmed content), `None` when no file is configured; a file
    /// that cannot be read, that group or others may access, that is empty or whose token is
    /// shorter than [`MIN_TOKEN_CHARS`] is an error naming it and saying how to fix it.
    pub fn read(file: Option<&Path>) -> anyhow::Result<Option<Token>> {
        let Some(file) = file else { return Ok(None) };
        let cannot_read = || format!("{}: cannot read the HTTP token file ([http] token_file)", file.display());
        let mode = std::fs::metadata(file).with_context(cannot_read)?.permissions().mode();
        if mode & GROUP_OTHER_MODE != 0 {
            anyhow::bail!(
                "{f}: the HTTP token file ([http] token_file) may be read or written by group or others \
                 (mode {:04o}); run `chmod 600 {f}`",
                mode & 0o7777,
                f = file.display()
            );
        }
        let text = std::fs::read_to_string(file).with_context(cannot_read)?;
        let token = Token::parse(&text)
            .with_context(|| format!("{}: the HTTP token file ([http] token_file) is empty", file.display()))?;
        let chars = token.0.chars().count();
        if chars < MIN_TOKEN_CHARS {
            anyhow::bail!(
                "{}: the HTTP token ([http] token_file) has {chars} characters, at least {MIN_TOKEN_CHARS} are \
                 needed (for example `openssl rand -hex 16`)",
                file.display()
            );
        }
        Ok(Some(token))
    }

    /// The token in a file's text: trimmed, `None` when nothing is left.
    pub fn parse(text: &str) -> Option<Token> {
        let t = text.trim();
        (!t.is_empty()).then(|| Token(Arc::from(t)))
    }

    fn matches(&self, presented: &str) -> bool {
        bool::from(self.0.as_bytes().ct_eq(presented.as_bytes()))
    }

    /// Whether a request with these headers, this method and this query may pass.
    pub fn admits(&self, method: &Method, headers: &HeaderMap, query: Option<&str>) -> bool {
        let bearer = headers
            .get_all(header::AUTHORIZATION)
            .iter()
            .filter_map(|v| v.to_str().ok())
            .filter_map(bearer_credentials)
            .any(|t| self.matches(t));
        if bearer {
            return true;
        }
        let readonly = method == Method::GET || method == Method::HEAD;
        readonly
            && query
                .and_then(|q| Query::<Vec<(String, String)>>::try_from_uri(&format!("/?{q}").parse().ok()?).ok())
                .is_some_and(|Query(pairs)| pairs.iter().any(|(k, v)| k == TOKEN_QUERY && self.matches(v)))
    }
}

/// The credentials of an `Authorization` value in the `Bearer` scheme, the scheme matched
/// without regard to case (RFC 7235 §2.1, RFC 6750 §2.1); `None` for another scheme.
fn bearer_credentials(value: &str) -> Option<&str> {
    let (scheme, credentials) = value.trim_start().split_once([' ', '\t'])?;
    scheme.eq_ignore_ascii_case("bearer").then(|| credentials.trim())
}

/// Middleware: pass every request when no token is configured, otherwise only those that
/// present it (`Token::admits`), and mark their connection admitted (`http_server`: it is
/// not shed for a newcomer); refuse the others with 401 and close their connection, so a
/// client without the token holds a connection for one request at most.
pub async fn require_token(State(token): State<Option<Token>>, req: Request, next: Next) -> Response {
    match &token {
        Some(t) if !t.admits(req.method(), req.headers(), req.uri().query()) => {
            tracing::debug!(path = %req.uri().path(), "HTTP request refused: no valid bearer token");
            (
                StatusCode::UNAUTHORIZED,
                [(header::WWW_AUTHENTICATE, "Bearer"), (header::CONNECTION, "close")],
                "this forgemon needs its token: `Authorization: Bearer <token>` (or `?token=<token>` on a GET)\n",
            )
                .into_response()
        }
        _ => {
            if let Some(admission) = req.extensions().get::<Admission>() {
                admission.admit();
            }
            next.run(req).await
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(auth: &[&str]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for a in auth {
            h.append(header::AUTHORIZATION, a.parse().unwrap());
        }
        h
    }

    /// A private file (mode 0600) holding `text`, in `dir`.
    fn token_file(dir: &Path, text: &str, mode: u32) -> std::path::PathBuf {
        let file = dir.join("token");
        std::fs::write(&file, text).unwrap();
        std::fs::set_permissions(&file, std::fs::Permissions::from_mode(mode)).unwrap();
        file
    }

    #[test]
    fn the_token_is_the_files_trimmed_content_and_an_empty_file_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = token_file(dir.path(), "  s3cret-s3cret-16\n", 0o600);
        let t = Token::read(Some(&file)).unwrap().unwrap();
        assert!(t.matches("s3cret-s3cret-16") && !t.matches("s3cret-s3cret-16\n") && !t.matches("s3cret-s3cret-1"));
        let file = token_file(dir.path(), " \n\t", 0o400);
        let e = format!("{:#}", Token::read(Some(&file)).unwrap_err());
        assert!(e.contains(&file.display().to_string()) && e.contains("empty"), "{e}");
        let missing = dir.path().join("absent");
        let e = format!("{:#}", Token::read(Some(&missing)).unwrap_err());
        assert!(e.contains(&missing.display().to_string()) && e.contains("cannot read"), "{e}");
        assert!(Token::read(None).unwrap().is_none());
    }

    /// Issue 39: checked as ssh checks a key: no access for group or others, the fix named.
    #[test]
    fn a_token_file_others_may_read_or_a_short_token_is_refused_saying_how_to_fix_it() {
        let dir = tempfile::tempdir().unwrap();
        for mode in [0o644, 0o640, 0o604, 0o666, 0o620, 0o602] {
            let file = token_file(dir.path(), "0123456789abcdef", mode);
            let e = format!("{:#}", Token::read(Some(&file)).unwrap_err());
            assert!(e.contains(&format!("chmod 600 {}", file.display())), "{mode:o}: {e}");
            assert!(e.contains(&format!("{mode:04o}")), "{e}");
        }
        let file = token_file(dir.path(), "0123456789abcde\n", 0o600);
        let e = format!("{:#}", Token::read(Some(&file)).unwrap_err());
        assert!(e.contains(&file.display().to_string()) && e.contains("15 characters, at least 16"), "{e}");
        let file = token_file(dir.path(), "0123456789abcdef\n", 0o600);
        assert!(Token::read(Some(&file)).unwrap().is_some_and(|t| t.matches("0123456789abcdef")));
    }

    #[test]
    fn a_request_passes_with_the_bearer_header_or_on_a_get_with_the_query() {
        let t = Token::parse("abc").unwrap();
        assert!(t.admits(&Method::GET, &headers(&["Bearer abc"]), None));
        assert!(t.admits(&Method::POST, &headers(&["Basic eA==", "Bearer abc"]), None));
        assert!(!t.admits(&Method::GET, &headers(&["Bearer abd"]), None));
        assert!(!t.admits(&Method::GET, &headers(&["abc"]), None), "the scheme is required");
        // RFC 7235 §2.1: the scheme is case-insensitive; one or more spaces follow it.
        for scheme in ["bearer abc", "BEARER abc", "BeArEr  abc", "Bearer\tabc"] {
            assert!(t.admits(&Method::GET, &headers(&[scheme]), None), "{scheme}");
        }
        for other in ["Bearerabc", "Bearer", "Bearer ", "Basic abc", "Bearer abc def"] {
            assert!(!t.admits(&Method::GET, &headers(&[other]), None), "{other}");
        }
        assert!(!t.admits(&Method::GET, &headers(&[]), None));
        assert!(t.admits(&Method::GET, &headers(&[]), Some("token=abc")));
        assert!(t.admits(&Method::GET, &headers(&[]), Some("x=1&token=abc")));
        assert!(!t.admits(&Method::GET, &headers(&[]), Some("token=ab")));
        assert!(!t.admits(&Method::GET, &headers(&[]), Some("tok%en=%%")), "garbage is refused");
        assert!(!t.admits(&Method::POST, &headers(&[]), Some("token=abc")), "a POST needs the header");
    }
}
