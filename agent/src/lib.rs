//! fdi-agent process (multi-process runtime).
