//! fdi-common: the math and the contracts every fdi-mas process shares.
//!
//! The system of Sargolzaei, Allen, Crane and Dixon, "Lyapunov-Based Control of a Nonlinear
//! Multiagent System With a Time-Varying Input Delay Under False-Data-Injection Attacks":
//! Euler–Lagrange agents ([`model`], [`plant`]), an attacker that injects false data into their
//! measurements ([`attack`]), and a control center with a nonlinear observer, an NN attack
//! estimator and a delay-compensating controller ([`control`]), over a delayed torque channel
//! ([`delay`]).
//!
//! Pure: no transport, no processes, no signals. The only I/O is on files named by the caller:
//! [`scenario`] reads scenario files (through [`files`]) and [`trace`] writes and reads trace
//! files; [`run_dir`] names the files of a run directory and [`stop`] is the value a caller
//! raises to stop a run (signal handlers are the caller's). The process side (transport,
//! process shell) is the `fdi-runtime` crate.
// A test reads top to bottom: the limit on long functions (clippy.toml) is for the rest.
#![cfg_attr(test, allow(clippy::too_many_lines))]

pub mod attack;
pub mod collect;
pub mod control;
pub mod delay;
pub mod detect;
pub mod engine;
pub mod field_path;
pub mod files;
pub mod json_float;
pub mod limits;
pub mod memo;
pub mod metrics;
pub mod model;
pub mod numerics;
pub mod observe;
pub mod overrides;
pub mod plant;
pub mod problem;
pub mod records;
pub mod rng;
pub mod roles;
pub mod run_dir;
pub mod scenario;
pub mod stop;
pub mod team;
pub mod time;
pub mod trace;
pub mod trajectory;
pub mod units;
pub mod urdf_files;
