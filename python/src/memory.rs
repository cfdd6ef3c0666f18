//! What memory this process uses and may still use, read from Linux's `/proc` and cgroup files:
//! the check that refuses a batch of environments too large for it before it is made.

/// This process's resident memory, bytes (`VmRSS` of `/proc/self/status`).
pub fn resident() -> Option<u64> {
    status_kib("VmRSS:").map(|k| k * 1024)
}

/// `KEY` of `/proc/self/status`, in KiB.
fn status_kib(key: &str) -> Option<u64> {
    let text = std::fs::read_to_string("/proc/self/status").ok()?;
    kib(&text, key)
}

/// The value in kB of the line `key … kB` of `text` (`/proc/meminfo`, `/proc/self/status`).
fn kib(text: &str, key: &str) -> Option<u64> {
    text.lines()
        .find_map(|l| l.strip_prefix(key))
        .and_then(|rest| rest.split_whitespace().next())
        .and_then(|v| v.parse().ok())
}

/// How much more memory this process may use, bytes: the least of the machine's available
/// memory (`MemAvailable`), what its cgroup's `memory.max` leaves, and what its address-space
/// limit (`ulimit -v`) leaves. None when nothing can be read.
pub fn available() -> Option<u64> {
    let machine = std::fs::read_to_string("/proc/meminfo")
        .ok()
        .and_then(|t| kib(&t, "MemAvailable:"))
        .map(|k| k * 1024);
    let cgroup = cgroup_left();
    let address_space = address_space_left();
    [machine, cgroup, address_space].into_iter().flatten().min()
}

/// What the cgroup v2 of this process leaves below its `memory.max`.
fn cgroup_left() -> Option<u64> {
    let own = std::fs::read_to_string("/proc/self/cgroup").ok()?;
    let path = own.lines().find_map(|l| l.strip_prefix("0::"))?;
    let dir = std::path::Path::new("/sys/fs/cgroup").join(path.trim_start_matches('/'));
    let read = |f: &str| std::fs::read_to_string(dir.join(f)).ok();
    let max: u64 = read("memory.max")?.trim().parse().ok()?;
    let current: u64 = read("memory.current")?.trim().parse().ok()?;
    Some(max.saturating_sub(current))
}

/// What `RLIMIT_AS` leaves above this process's address space (`VmSize`).
fn address_space_left() -> Option<u64> {
    let limit = std::fs::read_to_string("/proc/self/limits").ok()?;
    let line = limit.lines().find(|l| l.starts_with("Max address space"))?;
    let soft: u64 = line.split_whitespace().nth(3)?.parse().ok()?;
    let size = status_kib("VmSize:")? * 1024;
    Some(soft.saturating_sub(size))
}

/// `83 KB`, `8.3 GB`: a size for a message.
pub fn human(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= 1e9 {
        format!("{:.1} GB", b / 1e9)
    } else if b >= 1e6 {
        format!("{:.1} MB", b / 1e6)
    } else {
        format!("{:.0} KB", b / 1e3)
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn sizes_are_read_from_proc_lines_and_said_in_units() {
        let text = "MemTotal:       24000000 kB\nMemAvailable:   12345 kB\n";
        assert_eq!(super::kib(text, "MemAvailable:"), Some(12345));
        assert_eq!(super::kib(text, "Nothing:"), None);
        assert_eq!(super::human(83_000), "83 KB");
        assert_eq!(super::human(8_300_000_000), "8.3 GB");
        assert!(super::resident().is_some_and(|r| r > 0));
        assert!(super::available().is_some_and(|a| a > 0));
    }
}
