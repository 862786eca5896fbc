//! What a SIGHUP reload can take of a changed service file, and what only a restart takes.
//! The service reloads its alert rules and its machine model; everything else in the file
//! is opened or started once (listeners, sources, the recording, the faces, the sheet the
//! estimator tracks billets with), so a change there is named as needing a restart and never
//! reported as applied. Pure code: the caller compares the file in force with the new one.

use super::service::ServiceConfig;

/// The keys of `new` that differ from `old` and that a reload does not take, by the names
/// the file spells them (`http.listen`, `sources`). Every field of the configuration is
/// named here: a new one does not compile until it is sorted into what a reload takes
/// (`machine`, `alerts`) or not.
pub fn needs_restart(old: &ServiceConfig, new: &ServiceConfig) -> Vec<&'static str> {
    let ServiceConfig {
        machine_path: _,
        alerts: _,
        process_path,
        recipe_path,
        recording_dir,
        rotate_bytes,
        rotate_seconds,
        keep_bytes,
        keep_days,
        min_free_bytes,
        http_listen,
        http_limits,
        plc_limits,
        foxglove_limits,
        http_token_file,
        plc_listen,
        foxglove_listen,
        opcua,
        webhook,
        plc_coil,
        new_billet_rise_m,
        idle_new_billet_s,
        encoder_at_die_m,
        encoder_direction,
        sources,
        // Follows from `sources`, which a reload does not take.
        absent_channels: _,
        advisor,
        uplink_mqtt,
        history,
        part,
        die_life,
        drift,
    } = new;
    let changed = [
        ("process", *process_path != old.process_path),
        ("recipe", *recipe_path != old.recipe_path),
        ("recording.dir", *recording_dir != old.recording_dir),
        ("recording.rotate_bytes", *rotate_bytes != old.rotate_bytes),
        ("recording.rotate_seconds", *rotate_seconds != old.rotate_seconds),
        ("recording.keep_bytes", *keep_bytes != old.keep_bytes),
        ("recording.keep_days", *keep_days != old.keep_days),
        ("recording.min_free_bytes", *min_free_bytes != old.min_free_bytes),
        ("http.max_connections, header_timeout_s, idle_timeout_s", *http_limits != old.http_limits),
        ("plc_server.idle_timeout_s, max_connections", *plc_limits != old.plc_limits),
        ("foxglove.max_clients, handshake_timeout_s, idle_timeout_s", *foxglove_limits != old.foxglove_limits),
        ("http.listen", *http_listen != old.http_listen),
        ("http.token_file", *http_token_file != old.http_token_file),
        ("plc_server.listen", *plc_listen != old.plc_listen),
        ("foxglove.listen", *foxglove_listen != old.foxglove_listen),
        ("opcua", *opcua != old.opcua),
        ("alerts.webhook", *webhook != old.webhook),
        ("alerts.plc_coil", *plc_coil != old.plc_coil),
        ("billets.new_billet_rise_m", *new_billet_rise_m != old.new_billet_rise_m),
        ("billets.idle_s", *idle_new_billet_s != old.idle_new_billet_s),
        ("billets.encoder_at_die_m", *encoder_at_die_m != old.encoder_at_die_m),
        ("encoder.direction", *encoder_direction != old.encoder_direction),
        ("sources", *sources != old.sources),
        ("advisor", *advisor != old.advisor),
        ("uplink.mqtt", *uplink_mqtt != old.uplink_mqtt),
        ("history", *history != old.history),
        ("part", *part != old.part),
        ("die_life", *die_life != old.die_life),
        ("drift", *drift != old.drift),
    ];
    changed.into_iter().filter(|(_, c)| *c).map(|(key, _)| key).collect()
}

#[cfg(test)]
mod tests {
    use std::path::PathBuf;

    use super::*;

    #[test]
    fn listeners_sources_and_the_recording_need_a_restart_and_the_alert_rules_do_not() {
        let old = ServiceConfig::minimal(PathBuf::from("m.toml"), PathBuf::from("rec"));
        assert!(needs_restart(&old, &old).is_empty());
        let mut new = old.clone();
        new.alerts.low_efficiency = 0.1;
        new.machine_path = PathBuf::from("adopted.toml");
        assert!(needs_restart(&old, &new).is_empty(), "taken by the reload");
        new.http_listen = "127.0.0.1:9999".parse().expect("an address");
        new.recording_dir = PathBuf::from("elsewhere");
        new.foxglove_listen = Some("127.0.0.1:8765".parse().expect("an address"));
        assert_eq!(needs_restart(&old, &new), ["recording.dir", "http.listen", "foxglove.listen"]);
    }
}
