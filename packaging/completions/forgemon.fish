# Print an optspec for argparse to handle cmd's options that are independent of any subcommand.
function __fish_forgemon_global_optspecs
    string join \n h/help V/version
end

function __fish_forgemon_needs_command
    # Figure out if the current invocation already has a command.
    set -l cmd (commandline -opc)
    set -e cmd[1]
    argparse -s (__fish_forgemon_global_optspecs) -- $cmd 2>/dev/null
    or return
    if set -q argv[1]
        # Also print the command, so this can be used to figure out what it is.
        echo $argv[1]
        return 1
    end
    return 0
end

function __fish_forgemon_using_subcommand
    set -l cmd (__fish_forgemon_needs_command)
    test -z "$cmd"
    and return 1
    contains -- $cmd[1] $argv
end

complete -c forgemon -n "__fish_forgemon_needs_command" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_needs_command" -s V -l version -d 'Print version'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "simulate" -d 'Simulate consecutive blows on a billet (or bare strikes) with the machine model'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "identify" -d 'Fit the machine model to reference blows (or bare strikes), with uncertainty'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "diagnose" -d 'Find where the model and the measurement part, and which unmodelled effect explains it'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "replay" -d 'Run a recording, capture CSV or capture directory through the live pipeline'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "import" -d 'Turn capture CSV files or a capture directory into an MCAP recording'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "export" -d 'Write the blow results of recordings as one table (CSV or Parquet), a row per blow'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "history" -d 'The quality record: query the history database, or rebuild it from recordings'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "inspect" -d 'Say what a recording holds: sources, rates, duration, blows, gaps, drops, alerts'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "run" -d 'The always-on service: acquire, segment, estimate, alert, record'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "demo" -d 'The service against a simulated hammer over a pty: no hardware needed'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "simulate-device" -d 'A simulated hammer or press driving a real transport (a pty), like a DAQ'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "advise" -d 'Plan the next blows from the billet\'s height to a target with the machine model'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "teach" -d 'Learn a part\'s recipe (windows and an envelope per blow) from good billets'
complete -c forgemon -n "__fish_forgemon_needs_command" -f -a "help" -d 'Print this message or the help of the given subcommand(s)'
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l machine -d 'The machine model (machine.toml)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l process -d 'The process sheet (process.toml); not needed with --bare' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l v0 -d 'Impact speed of each blow, m/s, comma separated: one blow per value' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l effect -d 'Switch on an effect: NAME:param=value[,param=value] (repeatable; overrides the machine file\'s [effects.NAME])' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l monte-carlo -d 'Monte Carlo precision study with N runs (hammer paper §2.5)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l seed -d 'Seed of the Monte Carlo draws' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l mc-v0-95 -d '95 % bound of the impact speed, m/s (paper Table 2)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l mc-friction-95 -d '95 % bound of the friction coefficient (paper Table 2)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l mc-load-95 -d '95 % bound of the load measurement, N (paper Table 2)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l trace -d 'Write the simulated time series to this CSV file' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l trace-dt -d 'Sample period of the trace, s' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l captures -d 'Also write the blows as a capture directory (blow_01.csv, ..., process.toml), the way a DAQ would have recorded them: approach, sensor offset and noise, 10 µm encoder. Where the sheet lists measured heights, the directory\'s sheet lists the simulated ones instead, after every blow, as a caliper reads them (0.01 mm). With --bare: bare strikes, blow_01.csv, ..., without a process sheet' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l capture-seed -d 'Seed of the capture noise' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l rtol -d 'Relative tolerance of the adaptive integrator' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l rk4-dt -d 'Use the fixed-step RK4 reference at this step, s, instead of the adaptive integrator' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l json -d 'Print one JSON object (docs/interfaces.md §4) instead of a table'
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -l bare -d 'Bare strikes: tool on tool, no billet; prints peak load and contact time'
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l kind -d 'Machine kind: hammer | screw_press' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l reference -d 'Capture directory of the reference blows (blow_01.csv, ...)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l process -d 'Process sheet of the billet (default: DIR/process.toml)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -s o -l out -d 'Where to write the identified machine.toml' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l initial -d 'Prior machine: the centre of the search bounds and the first start (default: the paper\'s machine of the kind). The press\'s sensor stiffness is taken from it' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l ram-kg -d 'The ram\'s mass from the machine\'s data sheet, kg: references without a load channel (the accelerometer and the encoder alone) see the ram\'s acceleration, not a force, so this mass is held and anchors the others. Default: the --initial machine\'s' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l fit-blows -d 'Blow numbers to fit, e.g. 1 or 1,3 (default: all); the others are predicted and reported as held out' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l starts -d 'Local searches (the prior plus random starts). Default: 8, and without a load channel `RAM_FORCE_STARTS`' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l seed -d 'Seed of the random starts and the Monte Carlo draws (the same seed, the same fit)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l monte-carlo -d 'Monte Carlo draws for the load bands' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l report -d 'The HTML report (default: the output with .html)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -l bare -d 'The references are bare strikes (tool on tool), not blows on a billet'
complete -c forgemon -n "__fish_forgemon_using_subcommand identify" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand diagnose" -l machine -d 'The identified machine model' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand diagnose" -l calib -d 'Capture directory of the calibration billet (effect parameters are fitted here)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand diagnose" -l holdout -d 'Capture directory of another billet, used only to measure' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand diagnose" -l out -d 'Where report.json, report.html and machine.toml (the machine with the verdict\'s effect adopted) go' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand diagnose" -l adopt -d 'Also write the machine with the verdict\'s effect over the --machine file (the old one kept as M.toml.bak): the one-step form for a user who trusts the verdict'
complete -c forgemon -n "__fish_forgemon_using_subcommand diagnose" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -l machine -d 'The machine model (machine.toml); defaults to the one stored in the recording, or the capture directory\'s machine.toml' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -l process -d 'The process sheet; defaults to the capture directory\'s process.toml, or the one stored in the recording' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -l service -d 'The service configuration whose alert rules (`[alerts]`) and billet detection (`[billets]`) to use; defaults to the one stored in the recording, else the defaults' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -l out -d 'Record the replay (samples, blows, results, alerts, billets, configuration) to this MCAP file' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -l recipe -d 'Judge every blow against this recipe (docs/interfaces.md §9, `forgemon teach`): the §5 `judgement`, and `nok` alerts, as the service would' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -l encoder-direction -d 'Which way the ram encoder counts: `down` (towards the lower die, docs/interfaces.md §1), `up` (away from it: read negated), or `auto` (each blow\'s approach tells); overrides the service file\'s `[encoder] direction`' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -l json -d 'One JSON object per blow (docs/interfaces.md §5) instead of a table'
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -l sequential -d 'Read each recording\'s chunks in turn on one thread, instead of ahead and in parallel. The output is the same, byte for byte'
complete -c forgemon -n "__fish_forgemon_using_subcommand replay" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand import" -s o -l out -d 'The recording to write' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand import" -l machine -d 'A machine model to store in the recording too' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand import" -l process -d 'A process sheet to store (defaults to the directory\'s process.toml)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand import" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand export" -l csv -d 'Write CSV (a header row, then one row per blow; an empty field where a value is `null`); `-` writes it to standard output' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand export" -l parquet -d 'Write Parquet (snappy-compressed; nullable columns where a value can be `null`); `-` writes it to standard output, when that is not a terminal' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand export" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and not __fish_seen_subcommand_from query rebuild spc report export serve help" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and not __fish_seen_subcommand_from query rebuild spc report export serve help" -f -a "query" -d 'Print the blows (or billets) of the history database, oldest first'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and not __fish_seen_subcommand_from query rebuild spc report export serve help" -f -a "rebuild" -d 'Make the history database from recordings: MCAP is the source of truth. Into an existing database it adds only the rows it lacks'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and not __fish_seen_subcommand_from query rebuild spc report export serve help" -f -a "spc" -d 'Process capability per blow of a recipe: mean, spread, Cp/Cpk against its windows, and the individuals/moving-range chart\'s limits'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and not __fish_seen_subcommand_from query rebuild spc report export serve help" -f -a "report" -d 'A shift\'s quality report as one HTML file: SPC per blow, I-MR charts, lots and die sets'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and not __fish_seen_subcommand_from query rebuild spc report export serve help" -f -a "export" -d 'A table of the history database as CSV or Parquet, under the same filters as query'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and not __fish_seen_subcommand_from query rebuild spc report export serve help" -f -a "serve" -d 'Serve the dashboard\'s history page over a database alone (no machine, no service)'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and not __fish_seen_subcommand_from query rebuild spc report export serve help" -f -a "help" -d 'Print this message or the help of the given subcommand(s)'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l db -d 'The history database (`[history] path`; by default `history.sqlite` in the recording directory)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l table -d 'Which table' -r -f -a "blows\t''
billets\t''"
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l since -d 'Rows at or after this time: RFC 3339 (2026-11-30T06:00:00Z) or a UTC date (2026-11-30)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l until -d 'Rows before this time (as --since)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l part -d 'Only this part id' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l lot -d 'Only this lot' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l die -d 'Only this die set' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l recipe -d 'Only rows of this recipe (its name)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l limit -d 'At most this many rows' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l nok -d 'Only blows judged NOK, or billets with one'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -l json -d 'One JSON object per row (every column) instead of a table'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from query" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from rebuild" -l db -d 'The database to write (created if missing)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from rebuild" -l keep-days -d 'Delete rows older than this many days before the newest (as `[history] keep_days`)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from rebuild" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -l db -d 'The history database' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -l recipe -d 'The recipe file (`forgemon teach`): its name selects the blows, its windows are the specification limits' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -l since -d 'Rows at or after this time: RFC 3339 (2026-11-30T06:00:00Z) or a UTC date (2026-11-30)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -l until -d 'Rows before this time (as --since)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -l part -d 'Only this part id' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -l lot -d 'Only this lot' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -l die -d 'Only this die set' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -l json -d 'One JSON object per blow and quantity instead of a table'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from spc" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l db -d 'The history database' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l recipe -d 'The recipe file: its name selects the blows, its windows are the limits' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l shift -d 'The shift\'s start: RFC 3339 or a UTC date' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l hours -d 'The shift\'s length, h' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l since -d 'Rows at or after this time: RFC 3339 (2026-11-30T06:00:00Z) or a UTC date (2026-11-30)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l until -d 'Rows before this time (as --since)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l part -d 'Only this part id' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l lot -d 'Only this lot' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -l die -d 'Only this die set' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -s o -l out -d 'Where to write the report' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from report" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l db -d 'The history database (`[history] path`; by default `history.sqlite` in the recording directory)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l table -d 'Which table' -r -f -a "blows\t''
billets\t''"
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l since -d 'Rows at or after this time: RFC 3339 (2026-11-30T06:00:00Z) or a UTC date (2026-11-30)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l until -d 'Rows before this time (as --since)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l part -d 'Only this part id' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l lot -d 'Only this lot' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l die -d 'Only this die set' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l recipe -d 'Only rows of this recipe (its name)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l csv -d 'Write CSV (a header row, then the rows oldest first; an empty field for NULL); `-` writes it to standard output' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l parquet -d 'Write Parquet (snappy-compressed; `wall_time` a UTC timestamp in ns); `-` writes it to standard output, when that is not a terminal' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -l nok -d 'Only blows judged NOK, or billets with one'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from export" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from serve" -l db -d 'The history database' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from serve" -l http -d 'Where to serve the page (loopback only)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from serve" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from help" -f -a "query" -d 'Print the blows (or billets) of the history database, oldest first'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from help" -f -a "rebuild" -d 'Make the history database from recordings: MCAP is the source of truth. Into an existing database it adds only the rows it lacks'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from help" -f -a "spc" -d 'Process capability per blow of a recipe: mean, spread, Cp/Cpk against its windows, and the individuals/moving-range chart\'s limits'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from help" -f -a "report" -d 'A shift\'s quality report as one HTML file: SPC per blow, I-MR charts, lots and die sets'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from help" -f -a "export" -d 'A table of the history database as CSV or Parquet, under the same filters as query'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from help" -f -a "serve" -d 'Serve the dashboard\'s history page over a database alone (no machine, no service)'
complete -c forgemon -n "__fish_forgemon_using_subcommand history; and __fish_seen_subcommand_from help" -f -a "help" -d 'Print this message or the help of the given subcommand(s)'
complete -c forgemon -n "__fish_forgemon_using_subcommand inspect" -l json -d 'Print one JSON object instead of text'
complete -c forgemon -n "__fish_forgemon_using_subcommand inspect" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand run" -l config -d 'The service configuration: /etc/forgemon/forgemon.toml once the package is installed; annotated examples in config/*.service.toml (packaged: /usr/share/doc/forgemon/examples)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand run" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l billets -d 'How many billets to forge (0: keep forging until Ctrl-C)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l interval -d 'Seconds between blows' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l dir -d 'Where to record' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l http -d 'Serve the dashboard and `/status` here (loopback only: the demo has no token); default: a free loopback port' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l plc -d 'Serve the PLC result image (Modbus TCP, docs/interfaces.md §8) here' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l foxglove -d 'Serve the Foxglove WebSocket protocol here' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l mqtt -d 'Publish Sparkplug B to this MQTT broker (`mqtt://host:port`, docs/interfaces.md §10), as group `forge`, node `forgemon`, device `machine`; queued under `--dir` while it is down' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l opcua -d 'Serve the OPC UA Metal Forming server here (`opc.tcp://127.0.0.1:4840`; loopback only: the demo\'s sessions are anonymous)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l opcua-nodesets -d 'With --opcua: the OPC Foundation\'s NodeSet2 files (Machinery, Machine Tools, Metal Forming and what they require; `[opcua] nodesets_dir`), whose types the machine\'s nodes are then instances of' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l rotate-mib -d 'Start a new recording file after this many MiB (`[recording] rotate_bytes`), as a long run\'s files are rotated; default: the service\'s 512 MiB' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l recipe -d 'Judge every blow against this recipe (`forgemon teach`), OK/NOK' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l target -d 'Run the live blow advisor towards this billet height, m: after each blow it plans the blows left (`[advisor]` in a service file)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l settings -d 'The hammer\'s impact speeds the advisor may choose from, m/s (its drop heights)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l without -d 'Simulate a hammer without this sensor (`load`, `acc` or `disp`): its DAQ sends the other two channels, and each blow is estimated from them (the `channels` of its result)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l dead -d 'Kill a channel of the simulated DAQ this many seconds into the run (`load@12.5`): from then on it reads 0. The service notices from the next blow, raises one `sensor` alert naming it, and estimates the blows without it' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l lot -d 'The lot the billets come from (`[part] lot`): on every blow and billet in the history database (`--dir`/history.sqlite) and the recording' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l die -d 'The die set in the hammer (`[part] die_set`), as --lot' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l fast -d 'Run as fast as possible instead of in real time, and end after the last billet (on a terminal the demo otherwise keeps its dashboard up until Ctrl-C)'
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -l scatter -d 'Forge each billet a little unlike the last, as a plant\'s billets come: its flow stress ±3 % and its friction ±3 % (one sd, drawn per billet, the same every run of a lot and die set), so the history\'s charts and SPC have a spread to show'
complete -c forgemon -n "__fish_forgemon_using_subcommand demo" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l machine -d 'The machine model (machine.toml)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l process -d 'The billet forged, again and again (process.toml)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l v0 -d 'Impact speed of each blow on a billet, m/s, comma separated' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l billets -d 'How many billets to forge (0: keep going until stopped)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l interval -d 'Seconds between blows' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l height-spread -d 'Billet heights vary by up to this fraction around the sheet\'s (the first billet is the sheet\'s own), so the service\'s billet detection and height tracking are exercised' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l billet-idle -d 'Seconds more the machine stands idle before each billet after the first' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l rate -d 'Sample rate, Hz (up to 100 kHz)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l effect -d 'Unmodelled effects to put into the simulated machine: NAME:param=value (repeatable)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l wire -d 'The byte format on the pty (`--transport pty`)' -r -f -a "binary\t'COBS frames with CRC-32C (docs/interfaces.md §7)'"
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l transport -d 'Where the samples go: a pty, a Modbus TCP server or a candump log file' -r -f -a "pty\t'A pty pair, in real time; the path to open is printed'
modbus-tcp\t'A Modbus TCP server with the block-mode sample ring at register 0, in real time'
candump\t'A `candump -L` log file, one CAN frame per sample (fixtures/can/hammer.dbc), or with `--can-fd` one CAN FD frame per 8 samples (config/hammer-canfd.dbc)'"
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l listen -d 'Modbus TCP: the address to listen on' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l out -d 'candump: the log file to write' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l garbage-every -d 'Garbage bytes before every N-th frame (0: never)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l corrupt-every -d 'Corrupt the CRC of every N-th frame (0: never)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l drop-every -d 'Drop every N-th frame (0: never)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -l can-fd -d 'candump: CAN FD frames, each a block of 8 samples (config/hammer-canfd.dbc), for the rates a classic bus cannot carry (50 kHz)'
complete -c forgemon -n "__fish_forgemon_using_subcommand simulate-device" -s h -l help -d 'Print help (see more with \'--help\')'
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -l machine -d 'The machine model (machine.toml), with its effects if it has any' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -l process -d 'The billet\'s process sheet (process.toml): its law, friction and original height' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -l h-now -d 'The billet\'s height now, m (0.112 for 112 mm)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -l target -d 'The height to reach, m (within ±0.5 mm; 0.04 for 40 mm)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -l settings -d 'The machine\'s impact speeds, m/s, comma separated (a hammer\'s drop heights); or give `--v-max` instead' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -l v-max -d 'Any impact speed up to this, m/s (a screw press\'s energy setting); or give `--settings` instead. Either supplies the speeds the plan may choose from' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -l blows-done -d 'Blows the billet already took (the machine\'s `thermal` effect counts them)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -l json -d 'Print one JSON object (docs/interfaces.md §9) instead of a table'
complete -c forgemon -n "__fish_forgemon_using_subcommand advise" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l machine -d 'The machine model (machine.toml)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l process -d 'The process sheet; defaults to each reference\'s own (capture directory or recording)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l reference -d 'Good billets: capture directories or recordings (a recording may hold several)' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -s o -l out -d 'Where to write the recipe' -r -F
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l name -d 'The part\'s name (default: the output file\'s name without `.recipe.toml`)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l k -d 'Windows are mean ± max(k·sd, tolerance)' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l tol-efficiency -d 'Efficiency tolerance, absolute' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l tol-plastic -d 'Plastic energy tolerance, a share of the learnt mean' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l tol-peak-load -d 'Peak load tolerance, a share of the learnt mean' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l tol-load -d 'The envelope\'s load tolerance, a share of the learnt peak load' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -l tol-compression-mm -d 'The envelope\'s widening along the compression, mm' -r
complete -c forgemon -n "__fish_forgemon_using_subcommand teach" -s h -l help -d 'Print help'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "simulate" -d 'Simulate consecutive blows on a billet (or bare strikes) with the machine model'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "identify" -d 'Fit the machine model to reference blows (or bare strikes), with uncertainty'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "diagnose" -d 'Find where the model and the measurement part, and which unmodelled effect explains it'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "replay" -d 'Run a recording, capture CSV or capture directory through the live pipeline'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "import" -d 'Turn capture CSV files or a capture directory into an MCAP recording'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "export" -d 'Write the blow results of recordings as one table (CSV or Parquet), a row per blow'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "history" -d 'The quality record: query the history database, or rebuild it from recordings'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "inspect" -d 'Say what a recording holds: sources, rates, duration, blows, gaps, drops, alerts'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "run" -d 'The always-on service: acquire, segment, estimate, alert, record'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "demo" -d 'The service against a simulated hammer over a pty: no hardware needed'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "simulate-device" -d 'A simulated hammer or press driving a real transport (a pty), like a DAQ'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "advise" -d 'Plan the next blows from the billet\'s height to a target with the machine model'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "teach" -d 'Learn a part\'s recipe (windows and an envelope per blow) from good billets'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and not __fish_seen_subcommand_from simulate identify diagnose replay import export history inspect run demo simulate-device advise teach help" -f -a "help" -d 'Print this message or the help of the given subcommand(s)'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and __fish_seen_subcommand_from history" -f -a "query" -d 'Print the blows (or billets) of the history database, oldest first'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and __fish_seen_subcommand_from history" -f -a "rebuild" -d 'Make the history database from recordings: MCAP is the source of truth. Into an existing database it adds only the rows it lacks'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and __fish_seen_subcommand_from history" -f -a "spc" -d 'Process capability per blow of a recipe: mean, spread, Cp/Cpk against its windows, and the individuals/moving-range chart\'s limits'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and __fish_seen_subcommand_from history" -f -a "report" -d 'A shift\'s quality report as one HTML file: SPC per blow, I-MR charts, lots and die sets'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and __fish_seen_subcommand_from history" -f -a "export" -d 'A table of the history database as CSV or Parquet, under the same filters as query'
complete -c forgemon -n "__fish_forgemon_using_subcommand help; and __fish_seen_subcommand_from history" -f -a "serve" -d 'Serve the dashboard\'s history page over a database alone (no machine, no service)'
