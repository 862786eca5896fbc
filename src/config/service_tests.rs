//! Tests of the service file's parsing (`service.rs`): every key, every error.

use super::*;
use crate::signal::sample::Role;

const GOOD: &str = r#"
machine = "hammer.machine.toml"
process = "/etc/forgemon/steel.process.toml"
[recording]
dir = "rec"
[alerts]
low_efficiency = 0.55
webhook = "http://127.0.0.1:9999/alerts"
[alerts.plc_coil]
address = "127.0.0.1:502"
unit = 1
coil = 7
[[sources]]
name = "daq"
kind = "serial"
path = "/dev/ttyUSB0"
[[sources.channels]]
role = "load_N"
gain = 10.0
[[sources.channels]]
role = "disp_m"
gain = 1e-6
offset = 0.1
[[sources.channels]]
role = "acc_mps2"
gain = 0.01
"#;

/// Issue 22: billet detection is tuned in `[billets]`, checked like every other key.
#[test]
fn billet_detection_is_tuned_in_its_table() {
    let c = parse_service("s.toml", Path::new("/"), GOOD).unwrap();
    assert_eq!((c.new_billet_rise_m, c.idle_new_billet_s), (None, crate::estimate::billet::DEFAULT_IDLE_NEW_BILLET_S));
    let set = GOOD.replace("[[sources]]", "[billets]\nnew_billet_rise_m = 0.005\nidle_s = 45.0\n[[sources]]");
    let c = parse_service("s.toml", Path::new("/"), &set).unwrap();
    assert_eq!((c.new_billet_rise_m, c.idle_new_billet_s), (Some(0.005), 45.0));
    let die = GOOD.replace("[[sources]]", "[billets]\nencoder_at_die_m = 0.5\n[[sources]]");
    assert_eq!(parse_service("s.toml", Path::new("/"), &die).unwrap().encoder_at_die_m, Some(0.5));
    let far = GOOD.replace("[[sources]]", "[billets]\nencoder_at_die_m = 1e3\n[[sources]]");
    let e = parse_service("s.toml", Path::new("/"), &far).unwrap_err().to_string();
    assert!(e.contains("billets.encoder_at_die_m"), "{e}");
    let bad = GOOD.replace("[[sources]]", "[billets]\nnew_billet_rise_m = 5.0\n[[sources]]");
    let e = parse_service("s.toml", Path::new("/"), &bad).unwrap_err().to_string();
    assert!(e.contains("billets.new_billet_rise_m"), "{e}");
    let typo = GOOD.replace("[[sources]]", "[billets]\nidle = 45.0\n[[sources]]");
    let e = parse_service("s.toml", Path::new("/"), &typo).unwrap_err().to_string();
    assert!(e.contains("unknown key 'idle' in [billets]"), "{e}");
}

/// A replay reads the thresholds from the recording's copy of the service file: the
/// same values and the same checks as the service, the rest of the file unread.
#[test]
fn the_pipeline_tuning_is_read_alone() {
    let set = GOOD.replace("[[sources]]", "[billets]\nnew_billet_rise_m = 0.005\nidle_s = 45.0\n[[sources]]");
    let t = parse_tuning("rec.mcap", &set).unwrap();
    assert_eq!(t, parse_service("s.toml", Path::new("/"), &set).unwrap().tuning());
    assert_eq!((t.new_billet_rise_m, t.idle_new_billet_s), (Some(0.005), 45.0));
    let bad = set.replace("idle_s = 45.0", "idle_s = -1.0");
    assert!(parse_tuning("rec.mcap", &bad).unwrap_err().to_string().contains("billets.idle_s"));
    assert_eq!(parse_tuning("rec.mcap", "").unwrap().alerts, AlertConfig::default());
}

/// Issue 16: the sensor-health rule is tuned in `[alerts]`, ranges and typos checked.
#[test]
fn the_sensor_rule_is_tuned_in_alerts() {
    let c = parse_service("s.toml", Path::new("/"), GOOD).unwrap();
    assert_eq!(
        (c.alerts.sensor_limit, c.alerts.sensor_k, c.alerts.sensor_n),
        (AlertConfig::DEFAULT_SENSOR_LIMIT, AlertConfig::DEFAULT_SENSOR_K, AlertConfig::DEFAULT_SENSOR_N)
    );
    let set = GOOD.replace("[alerts]\n", "[alerts]\nsensor_limit = 0.08\nsensor_k = 2\nsensor_n = 5\n");
    let c = parse_service("s.toml", Path::new("/"), &set).unwrap();
    assert_eq!((c.alerts.sensor_limit, c.alerts.sensor_k, c.alerts.sensor_n), (0.08, 2, 5));
    let e = |text: &str| parse_service("s.toml", Path::new("/"), text).unwrap_err().to_string();
    let big = e(&GOOD.replace("[alerts]\n", "[alerts]\nsensor_limit = 5.0\n"));
    assert!(big.contains("alerts.sensor_limit") && big.contains("1e-3..1"), "{big}");
    let k = e(&GOOD.replace("[alerts]\n", "[alerts]\nsensor_k = 5\nsensor_n = 4\n"));
    assert!(k.contains("alerts.sensor_k") && k.contains("exceeds sensor_n 4"), "{k}");
    let typo = e(&GOOD.replace("[alerts]\n", "[alerts]\nsensor_limt = 0.05\n"));
    assert!(typo.contains("unknown key 'sensor_limt' in [alerts]; did you mean 'sensor_limit'?"), "{typo}");
}

#[test]
fn a_full_configuration_parses_with_defaults() {
    let c = parse_service("s.toml", Path::new("/etc/forgemon"), GOOD).unwrap();
    assert_eq!(c.machine_path, PathBuf::from("/etc/forgemon/hammer.machine.toml"));
    assert_eq!(c.process_path, Some(PathBuf::from("/etc/forgemon/steel.process.toml")));
    assert_eq!(c.recording_dir, PathBuf::from("/etc/forgemon/rec"));
    assert_eq!(c.http_listen.to_string(), DEFAULT_HTTP_LISTEN);
    assert_eq!(c.alerts.low_efficiency, 0.55);
    assert_eq!(c.plc_coil.unwrap().coil, 7);
    let SourceSpec::Serial { baud, format, channels, .. } = &c.sources[0] else { panic!("a serial source") };
    assert_eq!((*baud, *format), (DEFAULT_BAUD, SerialFormat::Binary));
    assert_eq!(channels[1], ChannelSpec { role: Role::Disp, gain: 1e-6, offset: 0.1 });
}

#[test]
fn the_example_service_configs_parse_and_name_existing_files() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    for name in [
        "hammer-serial.service.toml",
        "hammer-can.service.toml",
        "hammer-canfd.service.toml",
        "press-modbus-serial.service.toml",
    ] {
        let text = std::fs::read_to_string(dir.join(name)).unwrap();
        let c = parse_service(name, &dir, &text).unwrap();
        assert!(c.machine_path.exists(), "{name}: {}", c.machine_path.display());
        assert!(c.process_path.as_ref().is_none_or(|p| p.exists()), "{name}");
        for s in &c.sources {
            // A CAN source's DBC file reads into its mapping (issue 16: the FD block).
            if let SourceSpec::Can(can) = s {
                let m = can.resolve().unwrap_or_else(|e| panic!("{name}: {e}")).mapping;
                assert_eq!((m.is_fd(), m.samples_per_frame()), (can.fd, can.samples_per_frame), "{name}");
            }
        }
    }
}

#[test]
fn a_modbus_source_reads_its_register_map() {
    use crate::acquire::modbus::{DataType, Mode, Transport, WordOrder};
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let text = std::fs::read_to_string(dir.join("press-modbus-serial.service.toml")).unwrap();
    let c = parse_service("press", &dir, &text).unwrap();
    let SourceSpec::Modbus(m) = &c.sources[1] else { panic!("a modbus source") };
    assert!(matches!(m.transport, Transport::Tcp { .. }) && matches!(m.mode, Mode::Poll));
    assert_eq!((m.map[0].address, m.map[0].data_type, m.map[0].word_order), (100, DataType::U32, WordOrder::BigEndian));
    assert_eq!(m.map[1].scale, 0.1);
    assert_eq!(m.timeout, std::time::Duration::from_millis(200));
    let e = parse_service("p", &dir, &text.replace("type = \"i16\"", "type = \"i8\"")).unwrap_err();
    assert!(e.to_string().contains("key 'sources[2].registers[2].type'"), "{e}");
}

#[test]
fn the_front_ends_read_their_addresses_and_a_wide_listen_needs_a_token() {
    let ok = |text: &str| parse_service("s.toml", Path::new("/etc/forgemon"), text).unwrap();
    let e = |text: &str| parse_service("s.toml", Path::new("/"), text).unwrap_err().to_string();
    let c = ok(GOOD);
    assert_eq!((c.http_token_file.as_ref(), c.plc_listen, c.foxglove_listen), (None, None, None));
    let c = ok(&format!("{GOOD}[plc_server]\nlisten = \"127.0.0.1:5020\"\n[foxglove]\nlisten = \"127.0.0.1:8765\"\n"));
    assert_eq!(c.plc_listen.map(|a| a.port()), Some(5020));
    assert_eq!(c.foxglove_listen.map(|a| a.port()), Some(8765));
    let wide = format!("{GOOD}[http]\nlisten = \"0.0.0.0:9187\"\n");
    let why = e(&wide);
    assert!(why.contains("key 'http.token_file'") && why.contains("not loopback"), "{why}");
    let c = ok(&format!("{wide}token_file = \"token\"\n"));
    assert_eq!(c.http_token_file, Some(PathBuf::from("/etc/forgemon/token")));
    assert!(e(&format!("{GOOD}[plc_server]\nlisten = \"plc\"\n")).contains("key 'plc_server.listen'"));
    assert!(e(&format!("{GOOD}[foxglove]\nport = 8765\n")).contains("unknown key 'port'"));
    // The recipe, relative to the service file's directory.
    let m = "machine = \"hammer.machine.toml\"\n";
    let c = ok(&GOOD.replace(m, &format!("{m}recipe = \"flange.recipe.toml\"\n")));
    assert_eq!(c.recipe_path, Some(PathBuf::from("/etc/forgemon/flange.recipe.toml")));
}

/// Issue 39: each server's cap and timeouts are keys of its table, with defaults, checked.
#[test]
fn the_servers_limits_are_keys_of_their_tables_with_defaults() {
    use crate::config::server_limits::{FoxgloveLimits, HttpLimits};
    use std::time::Duration;
    let ok = |text: &str| parse_service("s.toml", Path::new("/"), text).unwrap();
    let e = |text: &str| parse_service("s.toml", Path::new("/"), text).unwrap_err().to_string();
    let c = ok(GOOD);
    assert_eq!((c.http_limits, c.foxglove_limits), (HttpLimits::default(), FoxgloveLimits::default()));
    assert_eq!(HttpLimits::default().header_timeout, Duration::from_secs(10));
    let http = "[http]\nlisten = \"127.0.0.1:9187\"\n";
    let set = format!("{GOOD}{http}max_connections = 64\nheader_timeout_s = 2.5\nidle_timeout_s = 30\n");
    let c = ok(&set);
    assert_eq!(c.http_limits.max_connections, 64);
    assert_eq!(
        (c.http_limits.header_timeout, c.http_limits.idle_timeout),
        (Duration::from_millis(2500), Duration::from_secs(30))
    );
    let fox = "[foxglove]\nlisten = \"127.0.0.1:8765\"\n";
    let c = ok(&format!("{GOOD}{fox}max_clients = 4\nhandshake_timeout_s = 1\nidle_timeout_s = 5\n"));
    let f = c.foxglove_limits;
    assert_eq!(
        (f.max_clients, f.handshake_timeout, f.idle_timeout),
        (4, Duration::from_secs(1), Duration::from_secs(5))
    );
    for (text, key) in [
        (format!("{GOOD}{http}max_connections = 0\n"), "http.max_connections"),
        (format!("{GOOD}{http}header_timeout_s = -1.0\n"), "http.header_timeout_s"),
        (format!("{GOOD}{http}idle_timeout_s = 1e9\n"), "http.idle_timeout_s"),
        (format!("{GOOD}{fox}max_clients = 100000\n"), "foxglove.max_clients"),
        (format!("{GOOD}{fox}handshake_timeout_s = nan\n"), "foxglove.handshake_timeout_s"),
        (format!("{GOOD}{fox}idle_timeout_s = 0\n"), "foxglove.idle_timeout_s"),
    ] {
        let why = e(&text);
        assert!(why.contains(&format!("key '{key}'")), "{key}: {why}");
    }
    assert!(e(&format!("{GOOD}{http}max_conections = 5\n")).contains("did you mean"));
}

#[test]
fn errors_name_the_key() {
    let e = |text: &str| parse_service("s.toml", Path::new("/"), text).unwrap_err().to_string();
    assert_eq!(e(&GOOD.replace("machine = \"hammer.machine.toml\"\n", "")), "s.toml: missing key 'machine'");
    assert!(e(&GOOD.replace("kind = \"serial\"", "kind = \"usb\"")).contains("key 'sources[1].kind'"));
    assert!(
        e(&GOOD.replace("role = \"disp_m\"", "role = \"displacement\"")).contains("key 'sources[1].channels[2].role'")
    );
    assert!(e(&GOOD.replace("gain = 0.01", "gain = 0")).contains("key 'sources[1].channels[3].gain' must not be 0"));
    assert!(e(&GOOD.replace("http://127.0.0.1:9999/alerts", "ftp://x")).contains("key 'alerts.webhook'"));
    assert!(
        e(&GOOD.replace("address = \"127.0.0.1:502\"", "address = \"plc\"")).contains("key 'alerts.plc_coil.address'")
    );
    assert!(e(&GOOD.replace("role = \"acc_mps2\"", "role = \"load_N\"")).contains("role load_N appears twice"));
    assert!(e(&format!("{GOOD}[http]\nlisten = \"nowhere\"\n")).contains("key 'http.listen'"));
}

fn error(text: &str) -> String {
    parse_service("s.toml", Path::new("/"), text).unwrap_err().to_string()
}

#[test]
fn misspelt_keys_are_refused_with_line_column_and_suggestion() {
    // GOOD starts with an empty line: [alerts] is on line 6, its first key on line 7.
    let e = error(&GOOD.replace("low_efficiency = 0.55", "hard_blwo = false"));
    assert_eq!(e, "s.toml:7:1: unknown key 'hard_blwo' in [alerts]; did you mean 'hard_blow'?");
    let e = error(&GOOD.replace("dir = \"rec\"", "dir = \"rec\"\nrotate_byte = 1048576"));
    assert_eq!(e, "s.toml:6:1: unknown key 'rotate_byte' in [recording]; did you mean 'rotate_bytes'?");
    let e = error(&GOOD.replace("path = \"/dev/ttyUSB0\"", "path = \"/dev/ttyUSB0\"\nbuad = 115200"));
    assert!(e.ends_with("unknown key 'buad' in [sources[1]]; did you mean 'baud'?"), "{e}");
    let e = error(&GOOD.replace("gain = 1e-6", "gian = 1e-6"));
    assert!(e.contains("unknown key 'gian' in [sources[1].channels[2]]; did you mean 'gain'?"), "{e}");
    let e = error(&GOOD.replace("coil = 7", "coils = 7"));
    assert!(e.contains("unknown key 'coils' in [alerts.plc_coil]; did you mean 'coil'?"), "{e}");
    let e = error(&format!("procss = \"p.toml\"\n{GOOD}"));
    assert_eq!(e, "s.toml:1:1: unknown key 'procss' at the top level; did you mean 'process'?");
    // A key far from every known one gets no suggestion, but is still refused.
    let e = error(&GOOD.replace("low_efficiency = 0.55", "colour = \"red\""));
    assert_eq!(e, "s.toml:7:1: unknown key 'colour' in [alerts]");
}

#[test]
fn byte_counts_are_whole_and_durations_cannot_overflow() {
    let rec = |extra: &str| GOOD.replace("dir = \"rec\"", &format!("dir = \"rec\"\n{extra}"));
    let e = error(&rec("rotate_bytes = 0.5"));
    assert_eq!(e, "s.toml:6:16: key 'recording.rotate_bytes' must be a whole number >= 0, not floating point `0.5`");
    let e = error(&rec("rotate_bytes = -1"));
    assert!(e.contains("key 'recording.rotate_bytes' must be a whole number >= 0"), "{e}");
    let e = error(&rec("rotate_bytes = 10"));
    assert!(e.contains("key 'recording.rotate_bytes' must be within 1048576..=1099511627776 bytes, got 10"), "{e}");
    let e = error(&rec("rotate_seconds = 9223372036854775807"));
    assert!(e.starts_with("s.toml:6:1: key 'recording.rotate_seconds' must be within 1..=31622400 s"), "{e}");
    let c = parse_service("s.toml", Path::new("/"), &rec("rotate_seconds = 86400\nrotate_bytes = 1073741824")).unwrap();
    assert_eq!((c.rotate_seconds, c.rotate_bytes), (86_400, 1 << 30));
    assert_eq!((c.keep_bytes, c.keep_days, c.min_free_bytes), (None, None, 2 << 30));
    let e = error(&rec("keep_bytes = 1000"));
    assert!(e.contains("key 'recording.keep_bytes' must be within 16777216..="), "{e}");
    let e = error(&rec("keep_days = 0"));
    assert!(e.contains("key 'recording.keep_days' must be finite and > 0, got 0"), "{e}");
    let e = error(&rec("min_free_bytes = -5"));
    assert!(e.contains("key 'recording.min_free_bytes' must be a whole number >= 0"), "{e}");
    let c =
        parse_service("s.toml", Path::new("/"), &rec("keep_bytes = 1073741824\nkeep_days = 30\nmin_free_bytes = 0"))
            .unwrap();
    assert_eq!((c.keep_bytes, c.keep_days, c.min_free_bytes), (Some(1 << 30), Some(30.0), 0));
    let e = error(&GOOD.replace("path = \"/dev/ttyUSB0\"", "path = \"/dev/ttyUSB0\"\nbaud = 1e20"));
    assert!(e.contains("key 'sources[1].baud' must be a whole number >= 0"), "{e}");
    let e = error(&GOOD.replace("path = \"/dev/ttyUSB0\"", "path = \"/dev/ttyUSB0\"\nbaud = 7"));
    assert!(e.contains("key 'sources[1].baud' must be within 300..=12000000 baud"), "{e}");
    let e = error(&GOOD.replace("unit = 1", "unit = 300"));
    assert!(e.contains("key 'alerts.plc_coil.unit' must be a whole number in 0..=255"), "{e}");
    let e = error(&GOOD.replace("low_efficiency = 0.55", "hard_blow = \"no\""));
    assert!(e.contains("key 'alerts.hard_blow' must be true or false"), "{e}");
    let e = error(&GOOD.replace("low_efficiency = 0.55", "k_low = 2.5"));
    assert!(e.contains("key 'alerts.k_low' must be a whole number"), "{e}");
}

/// The source checks no other test reaches: names, a missing address, path, ring
/// channels or register map, unit ids the Modbus spec reserves (248..=255), and named
/// registers whose `name=value` would not be one word of the status detail.
#[test]
fn source_and_modbus_errors_name_their_key() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let press = std::fs::read_to_string(dir.join("press-modbus-serial.service.toml")).unwrap();
    let e = |text: &str| parse_service("p", &dir, text).unwrap_err().to_string();
    let no_address = press.replace("address = \"192.168.0.10:502\"\nunit = 1\nmode", "unit = 1\nmode");
    assert!(e(&no_address).ends_with("missing key 'sources[2].address'"), "{}", e(&no_address));
    let rtu = press.replace("transport = \"tcp\"", "transport = \"rtu\"");
    assert!(e(&rtu).ends_with("missing key 'sources[2].path'"), "{}", e(&rtu));
    let unit = e(&press.replace("unit = 1\nmode", "unit = 248\nmode"));
    assert!(unit.contains("key 'sources[2].unit' must be 0..=247"), "{unit}");
    let block = e(&press.replace("mode = \"poll\"", "mode = \"block\""));
    assert!(block.ends_with("missing key 'sources[2].channels'"), "{block}");
    let no_map = press.split("[[sources.registers]]").next().unwrap().to_string();
    assert!(e(&no_map).ends_with("missing key 'sources[2].registers'"), "{}", e(&no_map));
    let twice = e(&press.replace("name = \"plc\"", "name = \"daq\""));
    assert!(twice.contains("key 'sources' ") && twice.contains("two sources are named 'daq'"), "{twice}");
    let bad_name = e(&press.replace("name = \"plc\"", "name = \"p l c\""));
    assert!(bad_name.contains("key 'sources[2].name' must be letters, digits, '_' or '-'"), "{bad_name}");
    let coil = e(&press.replace("unit = 1\ncoil = 12", "unit = 250\ncoil = 12"));
    assert!(coil.contains("key 'alerts.plc_coil.unit' must be 0..=247"), "{coil}");
    let spaced = e(&press.replace("name = \"setpoint_J\"", "name = \"setpoint J\""));
    assert!(spaced.contains("key 'sources[2].registers[1].name' must be a non-empty word"), "{spaced}");
    let own = e(&press.replace("name = \"setpoint_J\"", "name = \"timeouts\""));
    assert!(own.contains("must not be 'timeouts', a key the status detail already uses"), "{own}");
    let none = e(&format!("sources = []\n{}", GOOD.split("[[sources]]").next().unwrap()));
    assert!(none.contains("key 'sources' must be a non-empty array of tables ([[sources]])"), "{none}");
}

#[test]
fn modbus_and_can_sources_deny_unknown_keys_too() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config");
    let press = std::fs::read_to_string(dir.join("press-modbus-serial.service.toml")).unwrap();
    let e = parse_service("p", &dir, &press.replace("poll_ms = 500", "pol_ms = 500")).unwrap_err().to_string();
    assert!(e.contains("unknown key 'pol_ms' in [sources[2]]; did you mean 'poll_ms'?"), "{e}");
    let e = parse_service("p", &dir, &press.replace("word_order = \"big\"", "word_ordr = \"big\"")).unwrap_err();
    assert!(e.to_string().contains("in [sources[2].registers[1]]; did you mean 'word_order'?"), "{e}");
    let e = parse_service("p", &dir, &press.replace("transport = \"tcp\"", "transport = \"tpc\"")).unwrap_err();
    assert!(
        e.to_string()
            .contains("key 'sources[2].transport' must be \"tcp\" or \"rtu\", got \"tpc\"; did you mean \"tcp\"?"),
        "{e}"
    );
    let e = parse_service("p", &dir, &press.replace("poll_ms = 500", "poll_ms = 1e300")).unwrap_err();
    assert!(e.to_string().contains("key 'sources[2].poll_ms' must be within 1..3.6e6 ms"), "{e}");
    let can = std::fs::read_to_string(dir.join("hammer-can.service.toml")).unwrap();
    let e = parse_service("c", &dir, &can.replace("sample_rate_hz", "sample_rate_Hz")).unwrap_err().to_string();
    assert!(e.contains("unknown key 'sample_rate_Hz' in [sources[1]]; did you mean 'sample_rate_hz'?"), "{e}");
    let e = parse_service("c", &dir, &can.replace("acc_mps2 = \"Acc\"", "acc_mps = \"Acc\"")).unwrap_err();
    assert!(e.to_string().contains("in [sources[1].signals]; did you mean 'acc_mps2'?"), "{e}");
    // The CAN source's own checks are placed at their key too.
    let e = parse_service("c", &dir, &can.replace("sample_rate_hz = 5000", "sample_rate_hz = -5")).unwrap_err();
    assert!(e.to_string().starts_with("c:20:1: key 'sources[1].sample_rate_hz' must be finite and > 0"), "{e}");
}

/// Issue 20: `[advisor]` takes a target and exactly one of `settings` and `v_max`, each
/// checked against its physical range, the errors placed at the key.
#[test]
fn the_advisor_table_is_checked() {
    let with = |t: &str| GOOD.replace("[[sources]]", &format!("[advisor]\n{t}\n[[sources]]"));
    let c = parse_service("s.toml", Path::new("/"), GOOD).unwrap();
    assert_eq!(c.advisor, None);
    let c = parse_service("s.toml", Path::new("/"), &with("target_height_m = 0.03\nsettings = [3.9, 5.3]")).unwrap();
    let a = c.advisor.expect("configured");
    assert_eq!((a.target_height_m, a.speeds), (0.03, crate::advise::Speeds::Settings(vec![3.9, 5.3])));
    let c = parse_service("s.toml", Path::new("/"), &with("target_height_m = 0.012\nv_max = 0.45")).unwrap();
    assert_eq!(c.advisor.map(|a| a.speeds), Some(crate::advise::Speeds::UpTo(0.45)));
    let e = |t: &str| parse_service("s.toml", Path::new("/"), &with(t)).unwrap_err().to_string();
    assert!(e("target_height_m = 0.03").contains("settings = [m/s, ...] or v_max"), "{}", e("target_height_m = 0.03"));
    let both = e("target_height_m = 0.03\nsettings = [3.9]\nv_max = 5.0");
    assert!(both.contains("advisor.v_max") && both.contains("not both"), "{both}");
    let fast = e("target_height_m = 0.03\nsettings = [3.9, 300.0]");
    assert!(fast.contains("s.toml:") && fast.contains("advisor.settings[2]"), "{fast}");
    assert!(e("target_height_m = 30\nv_max = 5.0").contains("advisor.target_height_m"));
    assert!(e("target_height_m = 0.03\nsettings = []").contains("1 to 12 speeds"));
    assert!(e("target_heigth_m = 0.03\nv_max = 5.0").contains("target_height_m"), "a misspelt key is named");
}

/// `[encoder] direction` (issue 36): auto unless set, the three words, and a near miss named.
#[test]
fn the_encoders_direction_is_set_in_its_table() {
    use crate::estimate::EncoderDirection;
    let c = parse_service("s.toml", Path::new("/"), GOOD).unwrap();
    assert_eq!(c.encoder_direction, EncoderDirection::Auto);
    for (word, want) in
        [("auto", EncoderDirection::Auto), ("down", EncoderDirection::Down), ("up", EncoderDirection::Up)]
    {
        let set = GOOD.replace("[[sources]]", &format!("[encoder]\ndirection = \"{word}\"\n[[sources]]"));
        assert_eq!(parse_service("s.toml", Path::new("/"), &set).unwrap().encoder_direction, want);
        assert_eq!(parse_tuning("s.toml", &set).unwrap().encoder_direction, want);
    }
    let bad = GOOD.replace("[[sources]]", "[encoder]\ndirection = \"dwon\"\n[[sources]]");
    let e = parse_service("s.toml", Path::new("/"), &bad).unwrap_err().to_string();
    assert!(e.contains("key 'encoder.direction' must be") && e.contains("did you mean \"down\"?"), "{e}");
}

#[test]
fn the_plc_servers_limits_have_defaults_and_ranges_that_name_their_key() {
    let parse = |extra: &str| {
        parse_service("s.toml", Path::new("/"), &format!("{GOOD}[plc_server]\nlisten = \"127.0.0.1:5020\"\n{extra}"))
    };
    let c = parse("").unwrap();
    assert_eq!(c.plc_limits, PlcLimits::default());
    assert_eq!((c.plc_limits.idle_timeout_s, c.plc_limits.max_connections), (30.0, 16));
    let c = parse("idle_timeout_s = 1.5\nmax_connections = 3\n").unwrap();
    assert_eq!((c.plc_limits.idle_timeout_s, c.plc_limits.max_connections), (1.5, 3));
    for (bad, key) in [
        ("idle_timeout_s = 0.0\n", "plc_server.idle_timeout_s"),
        ("idle_timeout_s = inf\n", "plc_server.idle_timeout_s"),
        ("max_connections = 0\n", "plc_server.max_connections"),
    ] {
        let e = parse(bad).unwrap_err().to_string();
        assert!(e.contains("s.toml:") && e.contains(key), "{bad}: {e}");
    }
    let e = parse("idle_timeout = 3.0\n").unwrap_err().to_string();
    assert!(e.contains("did you mean 'idle_timeout_s'"), "{e}");
}
