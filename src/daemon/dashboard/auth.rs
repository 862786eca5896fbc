//! The HTTP server's bearer token (issue 19, security): when `[http] token_file` is set, every
//! request (`/status`, `/metrics`, `/billet`, the dashboard and its endpoints, `POST /ack`)
//! needs `Authorization: Bearer <token>`, the token being the file's trimmed content, read
//! once when the service starts. A browser's `EventSource` cannot send headers, so a `GET`
//! (the page, its state and its event stream) may carry the token as `?token=` instead; a
//! `POST` (`/ack`, `/billet`) needs the header, which the page's script sends, so no link or
//! foreign page can acknowledge or start a billet. Tokens are compared in constant time.

use std::path::Path;
use std::sync::Arc;

use anyhow::Context as _;
use axum::extract::{Query, Request, State};
use axum::http::{HeaderMap, Method, StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use subtle::ConstantTimeEq as _;

use crate::daemon::http_server::Admission;

/// The query parameter that carries the token on a `GET`.
pub const TOKEN_QUERY: &str = "token";

/// The secret every request must present.
#[derive(Clone)]
pub struct Token(Arc<str>);

impl std::fmt::Debug for Token {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Token(..)")
    }
}

impl Token {
    /// The token in `file` (its trimmed content), `None` when no file is configured; an
    /// unreadable or empty file is an error naming it.
    pub fn read(file: Option<&Path>) -> anyhow::Result<Option<Token>> {
        let Some(file) = file else { return Ok(None) };
        let text = std::fs::read_to_string(file)
            .with_context(|| format!("{}: cannot read the HTTP token file ([http] token_file)", file.display()))?;
        Token::parse(&text)
            .map(Some)
            .with_context(|| format!("{}: the HTTP token file ([http] token_file) is empty", file.display()))
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
            .filter_map(|v| v.strip_prefix("Bearer "))
            .any(|t| self.matches(t.trim()));
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

    #[test]
    fn the_token_is_the_files_trimmed_content_and_an_empty_file_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("token");
        std::fs::write(&file, "  s3cret\n").unwrap();
        let t = Token::read(Some(&file)).unwrap().unwrap();
        assert!(t.matches("s3cret") && !t.matches("s3cret\n") && !t.matches("s3cre"));
        std::fs::write(&file, " \n\t").unwrap();
        let e = format!("{:#}", Token::read(Some(&file)).unwrap_err());
        assert!(e.contains(&file.display().to_string()) && e.contains("empty"), "{e}");
        let missing = dir.path().join("absent");
        let e = format!("{:#}", Token::read(Some(&missing)).unwrap_err());
        assert!(e.contains(&missing.display().to_string()) && e.contains("cannot read"), "{e}");
        assert!(Token::read(None).unwrap().is_none());
    }

    #[test]
    fn a_request_passes_with_the_bearer_header_or_on_a_get_with_the_query() {
        let t = Token::parse("abc").unwrap();
        assert!(t.admits(&Method::GET, &headers(&["Bearer abc"]), None));
        assert!(t.admits(&Method::POST, &headers(&["Basic eA==", "Bearer abc"]), None));
        assert!(!t.admits(&Method::GET, &headers(&["Bearer abd"]), None));
        assert!(!t.admits(&Method::GET, &headers(&["abc"]), None), "the scheme is required");
        assert!(!t.admits(&Method::GET, &headers(&[]), None));
        assert!(t.admits(&Method::GET, &headers(&[]), Some("token=abc")));
        assert!(t.admits(&Method::GET, &headers(&[]), Some("x=1&token=abc")));
        assert!(!t.admits(&Method::GET, &headers(&[]), Some("token=ab")));
        assert!(!t.admits(&Method::GET, &headers(&[]), Some("tok%en=%%")), "garbage is refused");
        assert!(!t.admits(&Method::POST, &headers(&[]), Some("token=abc")), "a POST needs the header");
    }
}
