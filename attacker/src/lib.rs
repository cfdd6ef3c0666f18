//! fdi-attacker process (multi-process runtime).
