//! `fdi-launch sweep --shard K/N`: a campaign run as 3 shards in 3 processes at once into one
//! folder, then `--aggregate`, gives the bytes of the campaign run whole; so does a shard
//! killed mid-way and run again. Shards out of range, a campaign changed between shards, a
//! number of shards other than the folder's and a second copy of a running shard are refused,
//! and an aggregate with runs missing names the shard of each.

use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

use fdi_tests::{launch, spawn, wait_until, wait_with_watchdog, Scratch};

const WATCHDOG: Duration = Duration::from_secs(600);

/// 3 gains × 3 seeds of `duration_s` (100 s: about half a second a run, so that a shard can
/// be killed between its runs).
fn campaign(dir: &Path, file: &str, betas: &str, duration_s: f64) -> PathBuf {
    let p = dir.join(file);
    std::fs::write(
        &p,
        format!(
            "name = \"shards\"\n[set]\nduration_s = {duration_s:?}\n\
             [[axes]]\npath = \"controller.beta\"\nvalues = [{betas}]\n\
             [[axes]]\npath = \"seed\"\nrange = {{ start = 1, stop = 3, step = 1 }}\n"
        ),
    )
    .expect("campaign file");
    p
}

fn text(o: &Output) -> String {
    format!(
        "{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn sweep(c: &Path, out: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["sweep", c.to_str().expect("utf-8 path"), "--jobs", "1"];
    args.extend(extra);
    launch(&args, out, WATCHDOG)
}

fn ok(o: Output) -> String {
    assert!(o.status.success(), "{}", text(&o));
    text(&o)
}

fn read(p: PathBuf) -> Vec<u8> {
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// `results.csv` and `aggregate.csv` of `a` and `b` are byte for byte the same.
fn same_tables(a: &Path, b: &Path) {
    for f in ["results.csv", "aggregate.csv"] {
        assert!(
            read(a.join(f)) == read(b.join(f)),
            "{f} of {} and {} differ",
            a.display(),
            b.display()
        );
    }
}

#[test]
fn three_shards_at_once_and_a_killed_shard_run_again_aggregate_to_the_bytes_of_the_whole_campaign()
{
    let s = Scratch::new("shards");
    let c = campaign(&s.0, "c.toml", "10.0, 20.0, 30.0", 100.0);
    let whole = s.0.join("whole");
    ok(sweep(&c, &whole, &[]));
    let results = String::from_utf8(read(whole.join("results.csv"))).expect("utf-8");
    assert_eq!(results.lines().count(), 10, "{results}");
    assert!(!results.lines().next().unwrap_or("").contains("wall_s"));
    let timings = String::from_utf8(read(whole.join("timings.csv"))).expect("utf-8");
    assert_eq!(timings.lines().count(), 10, "{timings}");

    // Three shards at once into one folder.
    let sharded = s.0.join("sharded");
    let c_arg = c.to_str().expect("utf-8");
    let children: Vec<_> = (1..=3)
        .map(|k| {
            let shard = format!("{k}/3");
            spawn(
                &["sweep", c_arg, "--jobs", "1", "--shard", &shard],
                &sharded,
            )
        })
        .collect();
    let mut ran = 0;
    for child in children {
        let said = ok(wait_with_watchdog(child, WATCHDOG));
        // Every shard owns 3 of the 9 runs (equal costs).
        assert!(said.contains("3 of the campaign's 9 runs"), "{said}");
        ran += 3;
        assert!(
            !said.contains("results.csv"),
            "a shard writes no table: {said}"
        );
    }
    assert_eq!(ran, 9);
    assert!(!sharded.join("results.csv").exists());
    let said = ok(sweep(&c, &sharded, &["--aggregate"]));
    assert!(
        said.contains("9 of 9 runs in the tables (from 3 shards)"),
        "{said}"
    );
    same_tables(&whole, &sharded);

    // Shard 1 killed after its first run, the others run, shard 1 again.
    let killed = s.0.join("killed");
    let mut first = spawn(&["sweep", c_arg, "--jobs", "1", "--shard", "1/3"], &killed);
    let points = |dir: &Path| {
        std::fs::read_dir(dir.join("points")).map_or(0, |d| {
            d.flatten()
                .filter(|e| e.file_name().to_string_lossy().ends_with(".json"))
                .count()
        })
    };
    assert!(
        wait_until(Duration::from_secs(120), || points(&killed) >= 1),
        "shard 1 stored no result"
    );
    first.kill().expect("SIGKILL");
    first.wait().expect("reaped");
    assert!(points(&killed) < 3, "shard 1 was not killed mid-way");
    let status = ok(sweep(&c, &killed, &["--status"]));
    assert!(
        status.contains("stopped (its process is gone before its end)"),
        "{status}"
    );
    // An aggregate now: the tables of what is there, and the missing runs by shard.
    let partial = sweep(&c, &killed, &["--aggregate"]);
    assert_eq!(partial.status.code(), Some(1), "{}", text(&partial));
    let said = text(&partial);
    assert!(
        said.contains("runs are missing") && said.contains("shard 2/3 (not started): 3 runs"),
        "{said}"
    );
    for k in ["2/3", "3/3"] {
        ok(sweep(&c, &killed, &["--shard", k]));
    }
    let again = ok(sweep(&c, &killed, &["--shard", "1/3"]));
    assert!(
        again.contains("taking over the lease") && again.contains("is gone"),
        "{again}"
    );
    assert!(!again.contains("0 already done"), "{again}");
    let status = ok(sweep(&c, &killed, &["--status"]));
    assert!(status.contains("9 of 9 runs done, 0 failed"), "{status}");
    ok(sweep(&c, &killed, &["--aggregate"]));
    same_tables(&whole, &killed);
}

#[test]
fn shards_out_of_range_another_campaign_another_count_and_a_second_copy_are_refused() {
    let s = Scratch::new("shards-refused");
    let c = campaign(&s.0, "c.toml", "10.0, 20.0, 30.0", 0.4);
    let out = s.0.join("out");
    for bad in ["4/3", "0/3", "3"] {
        let o = sweep(&c, &out, &["--shard", bad]);
        assert_eq!(o.status.code(), Some(2), "{bad}: {}", text(&o));
        assert!(text(&o).contains("--shard"), "{bad}: {}", text(&o));
    }
    let o = sweep(&c, &out, &["--shard", "auto"]);
    assert!(
        !o.status.success() && text(&o).contains("neither SLURM_ARRAY_TASK_ID"),
        "{}",
        text(&o)
    );
    ok(sweep(&c, &out, &["--shard", "1/3"]));
    // The campaign edited: its runs are others, the folder's shards refuse it.
    let edited = campaign(&s.0, "edited.toml", "10.0, 20.0, 35.0", 0.4);
    for args in [&["--shard", "2/3"][..], &["--aggregate"], &["--status"]] {
        let o = sweep(&edited, &out, args);
        assert!(
            !o.status.success() && text(&o).contains("for another version of the campaign"),
            "{args:?}: {}",
            text(&o)
        );
    }
    // Another number of shards in the same folder.
    let o = sweep(&c, &out, &["--shard", "1/2"]);
    assert!(
        !o.status.success() && text(&o).contains("cut in 3 shards, not 2"),
        "{}",
        text(&o)
    );
    // A second copy of a running shard (runs long enough to still run).
    let long = campaign(&s.0, "long.toml", "10.0, 20.0, 30.0", 600.0);
    let long_out = s.0.join("long");
    let long_arg = long.to_str().expect("utf-8");
    let mut running = spawn(
        &["sweep", long_arg, "--jobs", "1", "--shard", "2/3"],
        &long_out,
    );
    assert!(wait_until(Duration::from_secs(60), || long_out
        .join("shards/2-of-3.json")
        .exists()));
    let o = sweep(&long, &long_out, &["--shard", "2/3"]);
    let still = running.try_wait().expect("polling").is_none();
    running.kill().expect("SIGKILL");
    running.wait().expect("reaped");
    assert!(still, "the first copy ended before the second was tried");
    assert!(
        !o.status.success() && text(&o).contains("a second copy of a shard is refused"),
        "{}",
        text(&o)
    );
    // Nothing of the first copy was lost or touched by the refused one.
    let record = String::from_utf8(read(long_out.join("shards/2-of-3.json"))).expect("utf-8");
    assert!(record.contains("\"state\": \"running\""), "{record}");
}
