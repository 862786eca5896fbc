//! The history database's schema, as migrations: migration `i` takes a database at
//! `PRAGMA user_version` `i` to `i + 1`. A released migration is never edited; a change is a
//! new one at the end. A database whose version is past the last is refused (a newer
//! forgemon wrote it).

/// The migrations in order; the schema's version is their count.
pub const MIGRATIONS: &[&str] = &[
    // 1: a row per blow (docs/interfaces.md §5 with the recipe's judgement and the part,
    // lot and die set it was forged on), a row per billet (its summary, `/billets`).
    "CREATE TABLE blows (
        id INTEGER PRIMARY KEY,
        wall_time_ns INTEGER NOT NULL,
        billet INTEGER NOT NULL,
        billet_blow INTEGER NOT NULL,
        blow INTEGER NOT NULL,
        t_contact_s REAL NOT NULL,
        v_impact_mps REAL,
        kinetic_in_J REAL,
        plastic_J REAL,
        friction_J REAL,
        damped_J REAL,
        elastic_J REAL,
        efficiency REAL,
        final_load_N REAL,
        peak_load_N REAL,
        h_start_m REAL,
        h_end_m REAL,
        class TEXT NOT NULL,
        gap_s REAL,
        sensor_check REAL,
        residual REAL,
        method TEXT,
        recipe TEXT,
        judgement TEXT,
        judgement_reasons TEXT,
        alert TEXT,
        alert_reason TEXT,
        part_id TEXT,
        lot TEXT,
        die_set TEXT,
        UNIQUE (wall_time_ns, blow)
    );
    CREATE INDEX blows_by_time ON blows (wall_time_ns);
    CREATE INDEX blows_by_part ON blows (part_id);
    CREATE INDEX blows_by_lot ON blows (lot);
    CREATE INDEX blows_by_die ON blows (die_set, wall_time_ns);
    CREATE INDEX blows_by_recipe ON blows (recipe, billet_blow);
    CREATE TABLE billets (
        id INTEGER PRIMARY KEY,
        wall_time_ns INTEGER NOT NULL,
        billet INTEGER NOT NULL,
        t_start_s REAL NOT NULL,
        t_end_s REAL NOT NULL,
        blows INTEGER NOT NULL,
        incomplete_blows INTEGER NOT NULL,
        implausible_blows INTEGER NOT NULL,
        energies_partial INTEGER NOT NULL,
        h_start_m REAL,
        h_start_off_sheet_m REAL,
        h_end_m REAL,
        kinetic_in_J REAL,
        plastic_J REAL,
        friction_J REAL,
        efficiency REAL,
        first_hard_blow INTEGER,
        hard_blows INTEGER NOT NULL,
        alerts INTEGER NOT NULL,
        checked_blows INTEGER NOT NULL,
        finished INTEGER NOT NULL,
        recipe TEXT,
        part_id TEXT,
        lot TEXT,
        die_set TEXT,
        UNIQUE (billet, t_start_s)
    );
    CREATE INDEX billets_by_time ON billets (wall_time_ns);
    CREATE INDEX billets_by_lot ON billets (lot);
    CREATE INDEX billets_by_die ON billets (die_set, wall_time_ns);",
    // 2: die life: one row per installation of a die set (a die change starts a new one),
    // with what it has taken (`die.rs`).
    "CREATE TABLE die_sets (
        id INTEGER PRIMARY KEY,
        die_set TEXT,
        installed_ns INTEGER NOT NULL,
        blows INTEGER NOT NULL,
        hard_blows INTEGER NOT NULL,
        energy_J REAL NOT NULL,
        blows_without_energy INTEGER NOT NULL,
        last_ns INTEGER
    );
    CREATE INDEX die_sets_by_name ON die_sets (die_set, id);
    -- One row per installation, however often its marker is ingested (an unnamed set as '',
    -- which no name can be).
    CREATE UNIQUE INDEX die_sets_once ON die_sets (COALESCE(die_set, ''), installed_ns);",
    // 3: a billet is known by its number, its start's device time and its first blow's log
    // time (`first_blow_ns`, 0 when it had no blow): two runs whose DAQ clocks both start at
    // zero (a power-cycled DAQ, the simulator) give their first billets the same number and
    // device time, and were one row. SQLite cannot drop a table's UNIQUE constraint, so the
    // table is made again; the rows there take their first blow's time from `blows`.
    "CREATE TABLE billets_v3 (
        id INTEGER PRIMARY KEY,
        wall_time_ns INTEGER NOT NULL,
        billet INTEGER NOT NULL,
        t_start_s REAL NOT NULL,
        t_end_s REAL NOT NULL,
        blows INTEGER NOT NULL,
        incomplete_blows INTEGER NOT NULL,
        implausible_blows INTEGER NOT NULL,
        energies_partial INTEGER NOT NULL,
        h_start_m REAL,
        h_start_off_sheet_m REAL,
        h_end_m REAL,
        kinetic_in_J REAL,
        plastic_J REAL,
        friction_J REAL,
        efficiency REAL,
        first_hard_blow INTEGER,
        hard_blows INTEGER NOT NULL,
        alerts INTEGER NOT NULL,
        checked_blows INTEGER NOT NULL,
        finished INTEGER NOT NULL,
        recipe TEXT,
        part_id TEXT,
        lot TEXT,
        die_set TEXT,
        first_blow_ns INTEGER NOT NULL DEFAULT 0
    );
    INSERT INTO billets_v3 SELECT *, COALESCE((SELECT min(b.wall_time_ns) FROM blows b WHERE b.billet = billets.billet
        AND b.t_contact_s >= billets.t_start_s AND b.t_contact_s <= billets.t_end_s
        AND b.wall_time_ns <= billets.wall_time_ns), 0) FROM billets;
    DROP TABLE billets;
    ALTER TABLE billets_v3 RENAME TO billets;
    CREATE UNIQUE INDEX billets_once ON billets (billet, t_start_s, first_blow_ns);
    CREATE INDEX billets_by_time ON billets (wall_time_ns);
    CREATE INDEX billets_by_lot ON billets (lot);
    CREATE INDEX billets_by_die ON billets (die_set, wall_time_ns);",
    // 4: the drift alarms' learnt references (`alert::drift::Reference` as JSON), each once:
    // the service resumes the latest after a restart.
    "CREATE TABLE drift_references (
        id INTEGER PRIMARY KEY,
        wall_time_ns INTEGER NOT NULL,
        reference TEXT NOT NULL UNIQUE
    );",
];
