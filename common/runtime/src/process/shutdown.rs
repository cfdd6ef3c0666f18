//! Stopping on SIGINT/SIGTERM or on the launcher's death.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;

/// Set when the process must stop: SIGINT, SIGTERM, or the launcher died.
#[derive(Debug, Clone)]
pub struct Shutdown {
    flag: Arc<AtomicBool>,
    launcher_pid: Option<u32>,
}

impl Shutdown {
    /// Registers SIGINT/SIGTERM handlers that only set a flag, and asks the kernel to send
    /// SIGTERM when the parent dies.
    pub fn install(launcher_pid: Option<u32>) -> std::io::Result<Self> {
        let flag = Arc::new(AtomicBool::new(false));
        signal_hook::flag::register(signal_hook::consts::SIGTERM, Arc::clone(&flag))?;
        signal_hook::flag::register(signal_hook::consts::SIGINT, Arc::clone(&flag))?;
        if launcher_pid.is_some() {
            rustix::process::set_parent_process_death_signal(Some(rustix::process::Signal::TERM))
                .map_err(std::io::Error::from)?;
        }
        Ok(Self { flag, launcher_pid })
    }

    /// A handle that is never triggered by signals (tests, in-process use).
    pub fn manual() -> Self {
        Self {
            flag: Arc::new(AtomicBool::new(false)),
            launcher_pid: None,
        }
    }

    pub fn request(&self) {
        self.flag.store(true, Ordering::SeqCst);
    }

    /// True once a stop was requested or the launcher is gone.
    pub fn requested(&self) -> bool {
        if self.flag.load(Ordering::Relaxed) {
            return true;
        }
        if let Some(pid) = self.launcher_pid {
            let parent = rustix::process::getppid().map(|p| p.as_raw_nonzero().get());
            if parent != i32::try_from(pid).ok() {
                self.request();
                return true;
            }
        }
        false
    }
}
