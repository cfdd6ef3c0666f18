//! Run prefixes, `fdi<launcher pid>_<tag>_` with a lowercase hexadecimal tag: the one place they
//! are formatted and parsed. A run's services and files all start with its prefix (iceoryx2's
//! `global.prefix`), so the launcher can find and remove what a killed run left behind, and tell
//! from the pid whether its launcher still lives.

use std::sync::atomic::{AtomicU64, Ordering};

/// One run's prefix.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct RunPrefix {
    text: String,
    launcher_pid: u32,
}

static NEXT: AtomicU64 = AtomicU64::new(0);

impl RunPrefix {
    /// The prefix of run `tag` of the launcher `launcher_pid`.
    pub fn new(launcher_pid: u32, tag: u64) -> Self {
        Self {
            text: format!("fdi{launcher_pid}_{tag:x}_"),
            launcher_pid,
        }
    }

    /// A prefix no other run of this process has had: the tag mixes the clock's nanoseconds
    /// (against a pid reused by a later launcher) with a counter (against two runs of one
    /// process in the same nanosecond tick).
    pub fn fresh() -> Self {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        Self::new(
            std::process::id(),
            (u64::from(nanos & 0xff_ffff) << 8) | (n & 0xff),
        )
    }

    /// The run prefix `name` (a file or service name) starts with, if it starts with one.
    pub fn parse_start(name: &str) -> Option<Self> {
        let rest = name.strip_prefix("fdi")?;
        let (pid, tail) = rest.split_once('_')?;
        let (tag, _) = tail.split_once('_')?;
        if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        if tag.is_empty() || !tag.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f')) {
            return None;
        }
        let launcher_pid = pid.parse::<u32>().ok()?;
        Some(Self {
            text: format!("fdi{pid}_{tag}_"),
            launcher_pid,
        })
    }

    /// What every prefix of the launcher `launcher_pid`'s runs starts with.
    pub fn of_launcher(launcher_pid: u32) -> String {
        format!("fdi{launcher_pid}_")
    }

    pub fn as_str(&self) -> &str {
        &self.text
    }

    pub fn launcher_pid(&self) -> u32 {
        self.launcher_pid
    }
}

impl std::fmt::Display for RunPrefix {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.text)
    }
}

#[cfg(test)]
mod tests {
    use super::RunPrefix;

    #[test]
    fn a_prefix_parses_back_from_any_name_that_starts_with_it() {
        for p in [
            RunPrefix::new(1, 0),
            RunPrefix::new(4_194_304, u64::MAX),
            RunPrefix::fresh(),
        ] {
            for name in [
                p.to_string(),
                format!("{p}fdi_wake_agent_3.event"),
                format!("{p}_x"),
            ] {
                assert_eq!(RunPrefix::parse_start(&name).as_ref(), Some(&p), "{name}");
            }
            assert!(p
                .as_str()
                .starts_with(&RunPrefix::of_launcher(p.launcher_pid())));
            assert!(p.as_str().len() <= super::super::MAX_PREFIX_LEN, "{p}");
        }
        assert_ne!(RunPrefix::fresh(), RunPrefix::fresh());
    }

    #[test]
    fn names_of_other_programs_are_not_prefixes() {
        for name in [
            "fdi",
            "fdi_1_",
            "fdi12__",
            "fdi12_ab",
            "fdix_ab_",
            "fdi12_fl0_",
            "fdi12_AB_",
            "iox2_fdi1_a_",
            "fdi-1_a_",
        ] {
            assert_eq!(RunPrefix::parse_start(name), None, "{name}");
        }
    }
}
