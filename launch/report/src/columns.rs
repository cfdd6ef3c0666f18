//! The columns of a run's records, named with their units: the one list that the CSV export
//! (a file per process, docs/traces.md) and the Python package's tick table (a row per robot
//! and tick, docs/python.md) are both made of.
//!
//! A vector is one column per link, `<stem><link><suffix>` with links from 1 (`q1_rad`,
//! `q2_rad`). The tick table joins the records of one tick: the key, the desired position, the
//! agent's, the attacker's, the true attack term, the control center's and, in a run that
//! attacks torques, the actuation path's columns; where a column of the files is text or its
//! name is another group's, the table says it as [`TICK_TABLE_FLAGS`] and
//! [`ACTUATION_IN_TABLE`] do.

/// What a column holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Type {
    Int,
    Float,
    /// `0`/`1` in a CSV file, a bool in the tick table.
    Flag,
    /// Words (`delivered`, `missing`, …), in the CSV files only.
    Text,
}

/// A group of columns: one, or one per link named `<stem><link><suffix>` (links from 1), whose
/// values are floats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Col {
    One(&'static str, Type),
    Links(&'static str, &'static str),
}

use Col::{Links, One};

/// Which tick of which robot, and when: the first columns of every file and of the table.
pub const KEY: &[Col] = &[
    One("k", Type::Int),
    One("agent", Type::Int),
    One("t_s", Type::Float),
];

/// What an agent records of a tick.
pub const AGENT: &[Col] = &[
    Links("q", "_rad"),
    Links("q", "_dot_rad_s"),
    Links("q", "_ddot_rad_s2"),
    Links("y", "_clean_rad"),
    Links("y", "_dot_clean_rad_s"),
    Links("u", "_applied_nm"),
    One("tau_s", Type::Float),
    One("missed", Type::Flag),
];

/// What the attacker records of a measurement.
pub const ATTACK: &[Col] = &[
    Links("alpha", "_pos_rad"),
    Links("alpha", "_vel_rad_s"),
    Links("y", "_tampered_rad"),
    Links("y", "_dot_tampered_rad_s"),
    One("active", Type::Flag),
    One("delivery", Type::Text),
];

/// What the attacker records of a torque, in a run that attacks torques.
pub const ACTUATION: &[Col] = &[
    Links("alpha", "_u_nm"),
    Links("u", "_tampered_nm"),
    One("held_s", Type::Float),
    One("active", Type::Flag),
    One("delivery", Type::Text),
];

/// The scenario's desired trajectory at the tick.
pub const DESIRED: &[Col] = &[
    Links("q", "_des_rad"),
    Links("q", "_dot_des_rad_s"),
    Links("q", "_ddot_des_rad_s2"),
];

/// The true attack term `S = S₂ + β S₁` of the tick, from the attacker's record.
pub const S_TRUE: &[Col] = &[Links("s", "_true_rad_s")];

/// What the control center records of a tick.
pub const CENTER: &[Col] = &[
    Links("s", "_hat_rad_s"),
    Links("q", "_hat_rad"),
    Links("q", "_dot_hat_rad_s"),
    Links("q", "_ddot_hat_rad_s2"),
    Links("u", "_sent_nm"),
    One("alarm", Type::Flag),
    One("rejected_input", Type::Flag),
    One("rejected_torque", Type::Flag),
    One("state_reset", Type::Flag),
    One("history_miss", Type::Flag),
    One("missing_input", Type::Flag),
];

/// A monitor program's verdict on a tick.
pub const MONITOR: &[Col] = &[
    One("alarm", Type::Flag),
    One("statistic", Type::Float),
    One("late", Type::Flag),
];

/// The CLOCK_MONOTONIC stamps of a torque's way, ns.
pub const LATENCY: &[Col] = &[
    One("agent_sent_ns", Type::Int),
    One("attacker_received_ns", Type::Int),
    One("attacker_sent_ns", Type::Int),
    One("center_received_ns", Type::Int),
    One("center_sent_ns", Type::Int),
    One("agent_received_ns", Type::Int),
];

/// The tick table's flags after the attacker's columns, in place of its text column: whether
/// the measurement was `delivered` to the center (`delivery` is `delivered`), and whether an
/// attack was in force on the robot at the tick (`attacked`, the ground truth of the
/// detectors).
pub const TICK_TABLE_FLAGS: &[Col] = &[One("delivered", Type::Flag), One("attacked", Type::Flag)];

/// The actuation path's columns in the tick table: those of [`ACTUATION`] without its text,
/// `active` named `actuation_active` (the attacker's measurement columns have an `active`).
pub const ACTUATION_IN_TABLE: &[Col] = &[
    Links("alpha", "_u_nm"),
    Links("u", "_tampered_nm"),
    One("held_s", Type::Float),
    One("actuation_active", Type::Flag),
];

/// The columns of the tick table, in order, for vectors of `links` links: the key, the desired
/// position (of [`DESIRED`]), the agent's, the attacker's, the true attack term, the flags,
/// the control center's and, when the run attacks torques (`actuation`), the actuation
/// path's; no text column.
pub fn tick_table(links: usize, actuation: bool) -> Vec<(String, Type)> {
    let mut groups = vec![KEY, &DESIRED[..1], AGENT, ATTACK, S_TRUE];
    groups.extend([TICK_TABLE_FLAGS, CENTER]);
    if actuation {
        groups.push(ACTUATION_IN_TABLE);
    }
    let mut columns = named(&groups, links);
    columns.retain(|(_, ty)| *ty != Type::Text);
    columns
}

/// The names and types of `groups`' columns for vectors of `links` links.
pub fn named(groups: &[&[Col]], links: usize) -> Vec<(String, Type)> {
    (groups.iter().flat_map(|g| g.iter()))
        .flat_map(|c| match *c {
            One(name, ty) => vec![(name.to_string(), ty)],
            Links(stem, suffix) => (1..=links)
                .map(|i| (format!("{stem}{i}{suffix}"), Type::Float))
                .collect(),
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_tick_table_names_each_column_once_and_takes_the_files_names() {
        for actuation in [false, true] {
            let table = tick_table(3, actuation);
            let mut names: Vec<&str> = table.iter().map(|(n, _)| n.as_str()).collect();
            assert!(table.iter().all(|(_, t)| *t != Type::Text));
            names.sort_unstable();
            let n = names.len();
            names.dedup();
            assert_eq!(names.len(), n, "a name twice: {names:?}");
        }
        let files = named(&[KEY, AGENT, ATTACK, DESIRED, S_TRUE, CENTER], 2);
        let table = tick_table(2, false);
        for (name, _) in &table {
            let derived = named(&[TICK_TABLE_FLAGS], 2).iter().any(|(d, _)| d == name);
            assert!(
                derived || files.iter().any(|(f, _)| f == name),
                "{name} is in no file"
            );
        }
        assert_eq!(table[3].0, "q1_des_rad");
        // The actuation path's columns are the file's, without its text, `active` renamed.
        let file: Vec<(String, Type)> = named(&[ACTUATION], 2)
            .into_iter()
            .filter(|(_, t)| *t != Type::Text)
            .map(|(n, t)| match n.as_str() {
                "active" => ("actuation_active".to_string(), t),
                _ => (n, t),
            })
            .collect();
        assert_eq!(file, named(&[ACTUATION_IN_TABLE], 2));
    }
}
