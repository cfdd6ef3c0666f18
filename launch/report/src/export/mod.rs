//! Trace export (`fdi-launch trace export RUN_DIR --format csv|mcap`): the binary traces of a run
//! as files that other tools open. Every column, topic and field is listed with its unit and
//! meaning in docs/traces.md.
//!
//! * CSV ([`csv`]): every `RUN_DIR/traces/<process>.trace` becomes `RUN_DIR/export/<process>.csv`
//!   (latency records `<process>-latency.csv`, the attacker's torque records
//!   `attacker-actuation.csv`, the events of every trace `events.csv`).
//! * MCAP ([`mcap`]): the whole run as `RUN_DIR/export/run.mcap`, one JSON topic per agent and
//!   stream, with a JSON schema per topic, for Foxglove and PlotJuggler.
//!
//! Both write the records of each kind in (tick, agent) order, with the tick time of
//! [`fdi_common::engine::tick_time`], and derive what the records do not hold (the desired
//! trajectory, the true attack term `S`) from the scenario in each trace's header. A damaged
//! trace is exported up to its last whole record, then the export fails naming the file and
//! the byte offset.
//!
//! An export never leaves a partial file: it is written under a temporary name in
//! `RUN_DIR/export` (`.run.mcap.*`, a folder `.csv.*` for the CSV files) and renamed into place
//! once every byte is on disk. A write that fails (a full disk, a read-only folder) abandons the
//! export: the temporary is removed, what `RUN_DIR/export` held before is left as it was, and
//! the error names the file and the cause (`no space left on device (ENOSPC)`).

mod csv;
mod detectors;
mod mcap;
mod sources;

use fdi_common::run_dir::RunDir;

use anyhow::Result;

/// The file format of an export.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// One CSV per process trace and record kind (pandas, MATLAB, a spreadsheet).
    Csv,
    /// One MCAP file per run, JSON messages with JSON schemas (Foxglove, PlotJuggler).
    Mcap,
}

/// Exports the traces of `run_dir` (`fdi-launch trace export RUN_DIR`), saying what each
/// trace gave (`said`, a line at a time: `<trace> -> <folder>: <n> records`) as it goes.
pub fn export(run: &RunDir, format: Format, said: &mut dyn FnMut(&str)) -> Result<()> {
    let run_dir = run.path();
    match format {
        Format::Csv => csv::export(run_dir, said),
        Format::Mcap => mcap::export(run_dir, said),
    }
}

#[cfg(test)]
mod tests {
    use fdi_common::records::AttackRecord;
    use fdi_common::trace::{TraceHeader, TraceWriter, FORMAT_VERSION};

    use super::sources::*;
    use fdi_common::trace::{TraceReader, TraceRecord};
    use std::path::{Path, PathBuf};

    /// A scratch run directory holding the fixture `testdata/short-run` (scenario and traces).
    pub(super) fn fixture_copy() -> tempfile::TempDir {
        let from = Path::new(env!("CARGO_MANIFEST_DIR")).join("testdata/short-run");
        let tmp = tempfile::tempdir().expect("a scratch folder");
        std::fs::create_dir(fdi_common::run_dir::RunDir::new(tmp.path()).traces())
            .expect("traces/");
        std::fs::copy(
            fdi_common::run_dir::RunDir::new(&from).scenario(),
            fdi_common::run_dir::RunDir::new(tmp.path()).scenario(),
        )
        .expect("copy");
        for e in std::fs::read_dir(fdi_common::run_dir::RunDir::new(&from).traces())
            .expect("the fixture's traces")
        {
            let p = e.expect("an entry").path();
            std::fs::copy(
                &p,
                fdi_common::run_dir::RunDir::new(tmp.path())
                    .traces()
                    .join(p.file_name().expect("name")),
            )
            .expect("copy");
        }
        tmp
    }

    fn attack(k: u64, agent: u32, tag: f64) -> TraceRecord {
        TraceRecord::Attack(AttackRecord {
            k,
            agent,
            alpha_position: Default::default(),
            alpha_velocity: Default::default(),
            y: fdi_common::records::Joints::from_slice(&[tag]),
            yd: Default::default(),
            active: false,
            delivery: Default::default(),
        })
    }

    fn tag(rec: &TraceRecord) -> f64 {
        match rec {
            TraceRecord::Attack(a) => a.y.as_slice()[0],
            other => panic!("not an attack record: {other:?}"),
        }
    }

    fn write(records: &[TraceRecord]) -> (tempfile::TempDir, PathBuf) {
        let dir = tempfile::tempdir().expect("scratch");
        let path = dir.path().join("attacker.trace");
        let header = TraceHeader {
            format_version: FORMAT_VERSION,
            process: "attacker".into(),
            scenario_toml: String::new(),
            seed: 1,
            clock: "lockstep".into(),
            kept: Default::default(),
        };
        let mut w = TraceWriter::create(&path, &header).expect("writer");
        for r in records {
            w.write(r).expect("write");
        }
        w.flush().expect("flush");
        (dir, path)
    }

    /// Agent 2's records written 10 000 ticks after agent 1's (each pipeline runs on its
    /// own) come out in (tick, agent) order; duplicates keep their file order.
    #[test]
    fn records_come_out_in_tick_then_agent_order_however_far_apart_they_were_written() {
        let mut recs: Vec<TraceRecord> = (0..10_000).map(|k| attack(k, 1, k as f64)).collect();
        recs.extend((0..3).map(|k| attack(k, 2, -(k as f64))));
        recs.push(attack(2, 2, -2.5));
        let (_dir, path) = write(&recs);
        let mut reader = TraceReader::open(&path).expect("reader");
        let mut n = 0;
        let mut got = Vec::new();
        read_sorted(&path, &mut reader, &mut n, |rec, _| {
            got.push(Kind::of(rec).map(|(_, k, a)| (k, a, tag(rec))));
            Ok(())
        })
        .expect("sorted");
        assert_eq!(n, 10_004);
        let head: Vec<_> = got.iter().take(7).flatten().copied().collect();
        assert_eq!(
            head,
            [
                (0, 1, 0.0),
                (0, 2, -0.0),
                (1, 1, 1.0),
                (1, 2, -1.0),
                (2, 1, 2.0),
                (2, 2, -2.0),
                (2, 2, -2.5)
            ]
        );
        assert_eq!(got.len(), 10_004);
        assert_eq!(got.last(), Some(&Some((9_999, 1, 9_999.0))));
    }

    #[test]
    fn a_stream_out_of_tick_order_is_refused_naming_the_record() {
        let (_dir, path) = write(&[attack(5, 1, 0.0), attack(4, 1, 0.0)]);
        let mut reader = TraceReader::open(&path).expect("reader");
        let mut n = 0;
        let e = read_sorted(&path, &mut reader, &mut n, |_, _| Ok(())).expect_err("out of order");
        let text = format!("{e:#}");
        assert!(
            text.contains("record 2") && text.contains("tick 4 of agent 1 comes after tick 5"),
            "{text}"
        );
    }
}
