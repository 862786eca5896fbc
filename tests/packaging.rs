//! The Debian package's contents (`cargo deb`, `[package.metadata.deb]` in Cargo.toml):
//! - the man pages (clap_mangen) and shell completions (clap_complete) under `packaging/`
//!   are what the command line generates now, so they cannot go stale;
//! - the package's `/etc/forgemon` holds a configuration the service accepts;
//! - every asset the metadata names exists, and the package installs each thing a plant
//!   needs (binary, unit, user, directories, configuration, examples, man pages,
//!   completions).
//!
//! `.ci/run` builds the package, installs it with `dpkg -i`, checks the installed unit with
//! `systemd-analyze verify` and removes it again.
//!
//! After a change to the command line: `FORGEMON_UPDATE_PACKAGING=1 cargo nextest run
//! --release --test packaging` rewrites the generated files.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use clap::CommandFactory;
use clap_complete::Shell;
use forgemon::cli::Cli;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The generated files by path under `packaging/`: a man page for `forgemon` and one per
/// command (`forgemon-run.1`, ...), and the bash, zsh and fish completions.
fn generated() -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let cmd = Cli::command();
    let mut page = |name: String, cmd: clap::Command| {
        let mut buf = Vec::new();
        let shown = name.replacen('-', " ", 1);
        clap_mangen::Man::new(cmd.name(name.clone()).bin_name(shown)).render(&mut buf).expect("renders");
        out.insert(PathBuf::from(format!("man/{name}.1")), buf);
    };
    page("forgemon".to_string(), cmd.clone());
    for sub in cmd.get_subcommands().filter(|s| s.get_name() != "help") {
        page(format!("forgemon-{}", sub.get_name()), sub.clone());
    }
    for (shell, file) in [(Shell::Bash, "forgemon.bash"), (Shell::Zsh, "_forgemon"), (Shell::Fish, "forgemon.fish")] {
        let mut buf = Vec::new();
        clap_complete::generate(shell, &mut Cli::command(), "forgemon", &mut buf);
        out.insert(PathBuf::from(format!("completions/{file}")), buf);
    }
    out
}

#[test]
fn the_man_pages_and_completions_are_the_command_lines() {
    let dir = root().join("packaging");
    let files = generated();
    if std::env::var_os("FORGEMON_UPDATE_PACKAGING").is_some() {
        for (path, bytes) in &files {
            let to = dir.join(path);
            std::fs::create_dir_all(to.parent().expect("a parent")).expect("mkdir");
            std::fs::write(&to, bytes).expect("write");
        }
    }
    let stale: Vec<String> = files
        .iter()
        .filter(|(path, bytes)| std::fs::read(dir.join(path)).ok().as_ref() != Some(*bytes))
        .map(|(path, _)| path.display().to_string())
        .collect();
    assert!(
        stale.is_empty(),
        "packaging/ is stale for {stale:?}: run FORGEMON_UPDATE_PACKAGING=1 cargo nextest run --release --test packaging"
    );
    // One page per command, and no page for a command that is gone.
    let pages = std::fs::read_dir(dir.join("man")).expect("packaging/man").count();
    assert_eq!(pages, files.keys().filter(|p| p.starts_with("man")).count(), "packaging/man holds extra pages");
    let run = String::from_utf8_lossy(&files[Path::new("man/forgemon-run.1")]).into_owned();
    assert!(run.contains("\\-\\-config"), "forgemon-run(1) documents --config:\n{run}");
}

/// `[package.metadata.deb]` of Cargo.toml.
fn deb_metadata() -> toml::Table {
    let manifest: toml::Table =
        std::fs::read_to_string(root().join("Cargo.toml")).expect("Cargo.toml").parse().expect("TOML");
    manifest["package"]["metadata"]["deb"].as_table().expect("[package.metadata.deb]").clone()
}

#[test]
fn the_package_installs_what_a_plant_needs_from_files_that_exist() {
    let deb = deb_metadata();
    let assets: Vec<(String, String)> = deb["assets"]
        .as_array()
        .expect("assets")
        .iter()
        .map(|a| (a[0].as_str().expect("source").to_string(), a[1].as_str().expect("target").to_string()))
        .collect();
    for (source, _) in &assets {
        if source.starts_with("target/") {
            continue; // built by cargo deb
        }
        let (dir, pattern) = source.rsplit_once('/').unwrap_or((".", source));
        let found = match pattern.split_once('*') {
            None => root().join(source).is_file(),
            Some((pre, post)) => std::fs::read_dir(root().join(dir)).expect("the asset's directory").any(|e| {
                let name = e.expect("entry").file_name().to_string_lossy().into_owned();
                name.starts_with(pre) && name.ends_with(post)
            }),
        };
        assert!(found, "Cargo.toml's deb asset {source} matches no file");
    }
    let installs = |target: &str| assets.iter().any(|(_, t)| t.starts_with(target));
    for target in [
        "usr/bin/",
        "usr/lib/tmpfiles.d/forgemon.conf",
        "etc/forgemon/forgemon.toml",
        "usr/share/doc/forgemon/examples/",
        "usr/share/man/man1/",
        "usr/share/bash-completion/completions/forgemon",
        "usr/share/zsh/vendor-completions/",
        "usr/share/fish/vendor_completions.d/",
    ] {
        assert!(installs(target), "the package installs nothing to {target}");
    }
    // The unit and the service's user (`forgemon.sysusers`, to usr/lib/sysusers.d/) come
    // from systemd/ by cargo-deb's debhelper rules; the unit is installed but neither
    // enabled nor started before the configuration is edited.
    assert!(root().join("systemd/forgemon.sysusers").is_file());
    let units = deb["systemd-units"].as_table().expect("systemd-units");
    assert_eq!(units["unit-scripts"].as_str(), Some("systemd/"));
    assert!(root().join("systemd/forgemon.service").is_file());
    assert_eq!((units["enable"].as_bool(), units["start"].as_bool()), (Some(false), Some(false)));
    let postinst = std::fs::read_to_string(root().join("packaging/postinst")).expect("postinst");
    assert!(postinst.contains("#DEBHELPER#") && postinst.contains("systemd-sysusers forgemon.conf"));
}

#[test]
fn the_packaged_configuration_is_one_the_service_accepts() {
    // /etc/forgemon as the package lays it out, in a temporary directory.
    let deb = deb_metadata();
    let etc = tempfile::tempdir().expect("temp dir");
    for a in deb["assets"].as_array().expect("assets") {
        let (source, target) = (a[0].as_str().expect("source"), a[1].as_str().expect("target"));
        if let Some(name) = target.strip_prefix("etc/forgemon/") {
            std::fs::copy(root().join(source), etc.path().join(name)).expect("copy");
        }
    }
    let cfg = etc.path().join("forgemon.toml");
    let text = std::fs::read_to_string(&cfg).expect("forgemon.toml");
    let parsed = forgemon::config::service::parse_service(&cfg.display().to_string(), etc.path(), &text);
    let parsed = parsed.unwrap_or_else(|e| panic!("the packaged forgemon.toml is refused: {e}"));
    assert_eq!(parsed.recording_dir, Path::new("/var/lib/forgemon"), "the recording goes to the state directory");
    // The serial path is a stable by-id name the user fills in.
    assert!(text.contains("/dev/serial/by-id/"), "the packaged source names a by-id path");
    // The machine and process files it names are installed beside it.
    for name in ["machine.toml", "process.toml"] {
        assert!(etc.path().join(name).is_file(), "{name} is not installed in /etc/forgemon");
    }
}
