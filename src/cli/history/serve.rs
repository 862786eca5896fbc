//! `forgemon history serve --db DB [--http ADDR]`: the dashboard's history page over a
//! database alone (a copy on an office PC, a rebuilt one), without a machine or a service:
//! `http://ADDR/history`, until Ctrl-C. Loopback only: there is no token here.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, bail};
use clap::Args;

use super::existing;

#[derive(Debug, Args)]
pub struct ServeArgs {
    /// The history database.
    #[arg(long, value_name = "DB")]
    pub db: PathBuf,
    /// Where to serve the page (loopback only).
    #[arg(long, value_name = "ADDR", default_value = "127.0.0.1:9188")]
    pub http: SocketAddr,
}

pub fn run(a: ServeArgs) -> anyhow::Result<ExitCode> {
    existing(&a.db)?;
    if !a.http.ip().is_loopback() {
        bail!(
            "--http {}: loopback only (the page has no token; the service's [http] token_file guards other addresses)",
            a.http
        );
    }
    let rt = tokio::runtime::Runtime::new()?;
    rt.block_on(async {
        let listener =
            tokio::net::TcpListener::bind(a.http).await.with_context(|| format!("--http {}: cannot listen", a.http))?;
        let addr = listener.local_addr()?;
        println!("history page on http://{addr}/history (Ctrl-C stops)");
        let app = crate::daemon::dashboard::history_page::standalone(a.db.clone());
        axum::serve(listener, app)
            .with_graceful_shutdown(async {
                let _ = tokio::signal::ctrl_c().await;
            })
            .await
            .context("the history page's server stopped")
    })?;
    Ok(ExitCode::SUCCESS)
}
