//! The shipped Slurm job files run a campaign on a real scheduler: a single-node cluster
//! (Debian's slurmctld, slurmd and munge, started by the test) takes
//! `examples/cluster/slurm/submit.sh` as a real array job of 3 shards and the aggregate job
//! after it; the aggregate's tables are byte for byte those of the campaign run whole.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use fdi_tests::slurm::{skip_reason, Cluster};
use fdi_tests::{launch, launch_plain, launcher, repo_path, Scratch};

const WATCHDOG: Duration = Duration::from_secs(600);

#[test]
fn the_shipped_slurm_script_runs_a_campaign_as_an_array_job_and_aggregates_it() {
    let s = Scratch::new("slurm");
    let cluster = match Cluster::start(&s.0.join("cluster")) {
        Ok(c) => c,
        Err(e) => {
            eprintln!("{}", skip_reason(&e));
            return;
        }
    };
    let c = s.0.join("c.toml");
    std::fs::write(
        &c,
        "name = \"on-slurm\"\n[set]\nduration_s = 2.0\n\
         [[axes]]\npath = \"controller.beta\"\nvalues = [10.0, 20.0, 30.0]\n\
         [[axes]]\npath = \"seed\"\nrange = { start = 1, stop = 2, step = 1 }\n",
    )
    .expect("campaign");
    let whole = s.0.join("whole");
    let o = launch(
        &["sweep", c.to_str().expect("utf-8"), "--jobs", "2"],
        &whole,
        WATCHDOG,
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    let jobs = s.0.join("jobs");
    let out = s.0.join("shared").join("on-slurm");
    let all = submit_and_wait(&cluster, &c, &out, &jobs);
    // Each array task ran its own shard, found from Slurm's environment.
    for k in 1..=3 {
        assert!(
            all.contains(&format!(
                "campaign on-slurm, shard {k}/3: 2 of the campaign's 6 runs"
            )),
            "{all}"
        );
    }
    assert!(
        all.contains("6 of 6 runs in the tables (from 3 shards)"),
        "{all}"
    );
    same_tables(&whole, &out);

    // The scored benchmark is a campaign too: its suite (the paper's team) as a campaign file,
    // sent as an array job, gives in its aggregate the row of the suite run whole.
    let suite = s.0.join("suite.toml");
    let args = ["score", "--controller", "traditional", "--teams", "paper"];
    let printed = launch_plain(&[&args[..], &["--campaign"]].concat(), WATCHDOG);
    assert!(
        printed.status.success(),
        "{}",
        String::from_utf8_lossy(&printed.stderr)
    );
    std::fs::write(&suite, &printed.stdout).expect("the suite's campaign file");
    let whole = s.0.join("suite-whole");
    let o = launch(&[&args[..], &["--jobs", "2"]].concat(), &whole, WATCHDOG);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = s.0.join("shared").join("suite");
    let all = submit_and_wait(&cluster, &suite, &out, &s.0.join("suite-jobs"));
    assert!(
        all.contains("48 of 48 runs in the tables (from 3 shards)"),
        "{all}"
    );
    let row = |d: &Path| {
        std::fs::read(d.join("score.json")).unwrap_or_else(|e| panic!("{}: {e}", d.display()))
    };
    assert!(
        row(&whole) == row(&out),
        "the row of the shards differs from the row run whole"
    );
}

/// Submits `campaign` with the shipped script as an array job of 3 shards into `out`, from the
/// working folder `jobs`, waits for its aggregate job to complete, and returns the jobs' logs.
fn submit_and_wait(cluster: &Cluster, campaign: &Path, out: &Path, jobs: &Path) -> String {
    // The script as a user runs it: from a working folder, with fdi-launch named by FDI_LAUNCH.
    std::fs::create_dir_all(jobs).expect("jobs folder");
    let submitted = Command::new(repo_path("examples/cluster/slurm/submit.sh"))
        .args([campaign.as_os_str(), out.as_os_str()])
        .args(["3", "--cpus-per-task=1"])
        .current_dir(jobs)
        .env("SLURM_CONF", cluster.conf())
        .env("FDI_LAUNCH", launcher())
        .output()
        .expect("submit.sh");
    let said = String::from_utf8_lossy(&submitted.stdout).into_owned();
    assert!(
        submitted.status.success(),
        "{said}\n{}",
        String::from_utf8_lossy(&submitted.stderr)
    );
    let aggregate = said
        .lines()
        .find_map(|l| l.strip_prefix("aggregate: job "))
        .and_then(|l| l.split_whitespace().next())
        .unwrap_or_else(|| panic!("no aggregate job in: {said}"));
    let ended = cluster.wait_for_end(aggregate, Duration::from_secs(300));
    let logs = || {
        let mut all = String::new();
        for e in std::fs::read_dir(jobs).expect("jobs folder").flatten() {
            let text = std::fs::read_to_string(e.path()).unwrap_or_default();
            all.push_str(&format!(
                "--- {}:\n{text}\n",
                e.file_name().to_string_lossy()
            ));
        }
        format!("{all}{}", cluster.log("slurmctld"))
    };
    assert_eq!(
        ended,
        Some(("COMPLETED".to_string(), "0:0".to_string())),
        "the aggregate job did not complete:\n{}",
        logs()
    );
    logs()
}

fn same_tables(a: &Path, b: &Path) {
    for f in ["results.csv", "aggregate.csv"] {
        let read = |d: &Path| std::fs::read(d.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert!(read(a) == read(b), "{f} differs");
    }
}
