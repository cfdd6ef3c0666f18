//! fdi-control-center process (multi-process runtime).
