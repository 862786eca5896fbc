//! Everything the service needs, read and checked before anything opens: the service file,
//! the files it names and what the sources give. `forgemon run` starts from it, and a SIGHUP
//! reload (`reload.rs`) goes through the same check before it takes anything, so a reload
//! cannot take what a start would refuse.

use std::path::Path;

use anyhow::{Context, bail};

use super::ServiceParts;
use crate::acquire::modbus::Mode;
use crate::acquire::modbus::registers::Signal;
use crate::config::parse_machine;
use crate::config::service::{ServiceConfig, SourceSpec, parse_service};
use crate::signal::sample::Role;

impl ServiceParts {
    /// Read and check everything the service file `config_path` names: the file itself, the
    /// machine model, the process sheet (its warnings back, for the caller to show), each CAN
    /// source's DBC file, the roles the sources give, the recipe, the HTTP token file and the
    /// OPC UA password file. Nothing is opened yet.
    pub fn load(config_path: &Path) -> anyhow::Result<(ServiceParts, Vec<String>)> {
        let text = read_text(config_path)?;
        let base = config_path.parent().unwrap_or(Path::new("."));
        let config: ServiceConfig = parse_service(&config_path.display().to_string(), base, &text)?;
        let machine_text = read_text(&config.machine_path).context("key 'machine'")?;
        let machine_file = parse_machine(&config.machine_path.display().to_string(), &machine_text)?;
        let (machine, effects) = (machine_file.machine, machine_file.effect_set());
        let mut warnings = Vec::new();
        let (process, process_text) = match &config.process_path {
            Some(p) => {
                let t = read_text(p).context("key 'process'")?;
                let sheet = crate::config::parse_process_sheet(&p.display().to_string(), &t)?;
                warnings.extend(sheet.warnings);
                if sheet.value.machine != machine.kind() {
                    bail!(
                        "{}: key 'machine' is \"{}\" but {} has kind \"{}\"",
                        p.display(),
                        sheet.value.machine.as_str(),
                        config.machine_path.display(),
                        machine.kind().as_str()
                    );
                }
                (Some(sheet.value), Some(t))
            }
            None => (None, None),
        };
        source_roles(&config, config_path)?;
        if let Some(name) = crate::estimate::unhonoured(&effects, process.as_ref()) {
            bail!(
                "{}: key 'effects.{name}': the estimator carries it in the model fit, which needs the billet's \
                 process sheet; set 'process' in {}",
                config.machine_path.display(),
                config_path.display()
            );
        }
        read_recipe(&config, machine.kind().as_str())?;
        check_secrets(&config)?;
        let parts = ServiceParts {
            config,
            config_path: config_path.to_path_buf(),
            config_text: text,
            machine,
            effects,
            machine_text,
            process,
            process_text,
            // A real DAQ cannot wait for the service.
            backpressure: crate::acquire::Backpressure::DropOldest,
        };
        Ok((parts, warnings))
    }
}

/// The text of `path`, or an error naming it.
pub(super) fn read_text(path: &Path) -> anyhow::Result<String> {
    std::fs::read_to_string(path).with_context(|| format!("{}: cannot read", path.display()))
}

/// `recipe`, read and checked (`config::recipe::parse_recipe`: the errors name the file, the
/// line and the key) and taught on a `kind`; its text, `None` without one.
pub(super) fn read_recipe(
    config: &ServiceConfig,
    kind: &str,
) -> anyhow::Result<Option<(crate::recipe::Recipe, String)>> {
    let Some(path) = &config.recipe_path else { return Ok(None) };
    let text = read_text(path).context("key 'recipe'")?;
    let recipe = crate::config::recipe::parse_recipe(&path.display().to_string(), &text)?;
    if recipe.machine != kind {
        bail!("{}: key 'machine': a recipe for a {} but the machine is a {kind}", path.display(), recipe.machine);
    }
    Ok(Some((recipe, text)))
}

/// The HTTP token file reads as a token (`dashboard::auth::Token::read`), and the OPC UA
/// password file can be read.
fn check_secrets(config: &ServiceConfig) -> anyhow::Result<()> {
    super::dashboard::auth::Token::read(config.http_token_file.as_deref())?;
    if let Some(crate::config::opcua::OpcuaAccess::User { password_file, .. }) =
        config.opcua.as_ref().map(|o| &o.access)
    {
        std::fs::File::open(password_file)
            .with_context(|| format!("{}: cannot read (key 'opcua.password_file')", password_file.display()))?;
    }
    Ok(())
}

/// Each source's roles, every CAN source's DBC file read (so that a bad one stops the start),
/// and the roles checked (`check_roles`).
fn source_roles(config: &ServiceConfig, config_path: &Path) -> anyhow::Result<()> {
    let mut roles: Vec<(&str, Vec<Role>)> = Vec::new();
    for s in &config.sources {
        let r = match s {
            SourceSpec::Can(c) => c.resolve().with_context(|| format!("source '{}'", c.name))?.mapping.roles(),
            SourceSpec::Serial { channels, .. } => channels.iter().map(|c| c.role).collect(),
            SourceSpec::Modbus(m) => match &m.mode {
                Mode::Poll => m
                    .map
                    .iter()
                    .filter_map(|r| match r.signal {
                        Signal::Role(role) => Some(role),
                        Signal::Named(_) => None,
                    })
                    .collect(),
                Mode::Block { channels, .. } => channels.iter().map(|c| c.role).collect(),
            },
        };
        roles.push((s.name(), r));
    }
    check_roles(&config_path.display().to_string(), &roles)
}

/// Every blow needs the load, the ram position and the acceleration: from one source, or
/// each from exactly one of several (merged onto the acceleration's timeline,
/// `signal::merge`). Checked before anything is opened.
fn check_roles(origin: &str, roles: &[(&str, Vec<Role>)]) -> anyhow::Result<()> {
    if roles.iter().any(|(_, r)| Role::ALL.iter().all(|x| r.contains(x))) {
        return Ok(());
    }
    for role in Role::ALL {
        let from: Vec<&str> = roles.iter().filter(|(_, r)| r.contains(&role)).map(|(n, _)| *n).collect();
        match from.as_slice() {
            [] => bail!("{origin}: key 'sources': no source gives {role} (a blow needs load_N, disp_m and acc_mps2)"),
            [_] => {}
            many => bail!(
                "{origin}: key 'sources': {role} comes from sources '{}'; with no source giving all three roles, \
                 give each role from one source",
                many.join("', '")
            ),
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_roles_must_be_covered_once() {
        let all = Role::ALL.to_vec();
        // One source with every role: others may repeat roles (they are recorded only).
        assert!(check_roles("s.toml", &[("daq", all.clone()), ("spare", vec![Role::Load])]).is_ok());
        // Split over two sources, each role once: merged.
        assert!(check_roles("s.toml", &[("daq", vec![Role::Load, Role::Acc]), ("enc", vec![Role::Disp])]).is_ok());
        let e = check_roles("s.toml", &[("daq", vec![Role::Load, Role::Acc])]).unwrap_err().to_string();
        assert!(e.contains("s.toml: key 'sources': no source gives disp_m"), "{e}");
        let e = check_roles("s.toml", &[("a", vec![Role::Load, Role::Acc]), ("b", vec![Role::Disp, Role::Load])])
            .unwrap_err()
            .to_string();
        assert!(e.contains("load_N comes from sources 'a', 'b'"), "{e}");
    }
}
