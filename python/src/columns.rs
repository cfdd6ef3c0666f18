//! Every tick of a run as columns (one row per robot and tick, in the trace digest's order),
//! named as the CSV export names its columns (docs/traces.md), for numpy arrays and a pandas
//! DataFrame on the Python side.

use std::collections::BTreeMap;

use fdi_common::model::{EulerLagrange, ForLinks};
use fdi_common::records::{true_s, Joints, TickRecord};
use fdi_common::scenario::Resolved;
use fdi_common::trajectory::TrajectoryConfig;
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyList};

/// The values of one column.
#[derive(Debug)]
enum Data {
    F64(Vec<f64>),
    I64(Vec<i64>),
    Bool(Vec<bool>),
}

/// The desired positions `q_d(t)` of a trajectory, `links` entries into `out`.
type DesiredFn = fn(&TrajectoryConfig, f64, &mut [f64]);

fn desired<const N: usize>(traj: &TrajectoryConfig, t: f64, out: &mut [f64]) {
    let q = traj.reference::<N>(t).q;
    for (o, v) in out.iter_mut().zip(q.iter()) {
        *o = *v;
    }
}

/// The columns of a run's ticks, filled record by record.
#[derive(Debug)]
pub struct Columns {
    links: usize,
    beta: f64,
    actuation: bool,
    trajectories: BTreeMap<u32, TrajectoryConfig>,
    desired: DesiredFn,
    names: Vec<String>,
    data: Vec<Data>,
    scratch: Vec<f64>,
}

/// Per link: `<stem><i><suffix>` for i from 1.
fn per_link<'a>(stem: &'a str, suffix: &'a str, links: usize) -> impl Iterator<Item = String> + 'a {
    (1..=links).map(move |i| format!("{stem}{i}{suffix}"))
}

impl Columns {
    /// The columns of `resolved`'s records; `actuation`: its records carry the torque path's.
    pub fn new(resolved: &Resolved, actuation: bool) -> Self {
        struct Pick;
        impl ForLinks for Pick {
            type Output = (usize, DesiredFn);
            fn call<const N: usize>(self, _: Box<dyn EulerLagrange<N>>) -> Self::Output {
                (N, desired::<N>)
            }
        }
        let (links, desired) = resolved.with_links(Pick).unwrap_or((0, desired::<0>));
        let s = &resolved.scenario;
        let mut c = Self {
            links,
            beta: s.controller.beta,
            actuation,
            trajectories: s
                .agents
                .iter()
                .map(|a| (a.id, a.trajectory.clone()))
                .collect(),
            desired,
            names: Vec::new(),
            data: Vec::new(),
            scratch: vec![0.0; links],
        };
        c.declare();
        c
    }

    fn declare(&mut self) {
        let l = self.links;
        let mut names: Vec<(String, u8)> = vec![("k".into(), b'i'), ("agent".into(), b'i')];
        let f = |stem: &str, suffix: &str| -> Vec<(String, u8)> {
            per_link(stem, suffix, l).map(|n| (n, b'f')).collect()
        };
        names.push(("t_s".into(), b'f'));
        for (stem, suffix) in [
            ("q", "_des_rad"),
            ("q", "_rad"),
            ("q", "_dot_rad_s"),
            ("q", "_ddot_rad_s2"),
            ("y", "_clean_rad"),
            ("y", "_dot_clean_rad_s"),
            ("u", "_applied_nm"),
        ] {
            names.extend(f(stem, suffix));
        }
        names.push(("tau_s".into(), b'f'));
        names.push(("missed".into(), b'b'));
        for (stem, suffix) in [
            ("alpha", "_pos_rad"),
            ("alpha", "_vel_rad_s"),
            ("y", "_tampered_rad"),
            ("y", "_dot_tampered_rad_s"),
            ("s", "_true_rad_s"),
        ] {
            names.extend(f(stem, suffix));
        }
        names.push(("active".into(), b'b'));
        names.push(("delivered".into(), b'b'));
        names.push(("attacked".into(), b'b'));
        for (stem, suffix) in [
            ("s", "_hat_rad_s"),
            ("q", "_hat_rad"),
            ("q", "_dot_hat_rad_s"),
            ("q", "_ddot_hat_rad_s2"),
            ("u", "_sent_nm"),
        ] {
            names.extend(f(stem, suffix));
        }
        for flag in [
            "alarm",
            "rejected_input",
            "rejected_torque",
            "state_reset",
            "history_miss",
            "missing_input",
        ] {
            names.push((flag.into(), b'b'));
        }
        if self.actuation {
            names.extend(f("alpha", "_u_nm"));
            names.extend(f("u", "_tampered_nm"));
            names.push(("held_s".into(), b'f'));
            names.push(("actuation_active".into(), b'b'));
        }
        for (name, kind) in names {
            self.names.push(name);
            self.data.push(match kind {
                b'i' => Data::I64(Vec::new()),
                b'b' => Data::Bool(Vec::new()),
                _ => Data::F64(Vec::new()),
            });
        }
    }

    /// Appends the row of one record.
    pub fn push(&mut self, r: &TickRecord) {
        let mut row = Row {
            data: &mut self.data,
            at: 0,
            links: self.links,
        };
        row.int(r.agent.k as i64);
        row.int(i64::from(r.agent.agent));
        row.float(r.agent.t);
        match self.trajectories.get(&r.agent.agent) {
            Some(traj) => {
                (self.desired)(traj, r.agent.t, &mut self.scratch);
                row.floats(&self.scratch);
            }
            None => row.floats(&[]),
        }
        let a = &r.agent;
        for j in [&a.q, &a.qd, &a.qdd, &a.y, &a.yd, &a.u_applied] {
            row.joints(j);
        }
        row.float(a.tau);
        row.flag(a.missed);
        let x = &r.attack;
        for j in [&x.alpha_position, &x.alpha_velocity, &x.y, &x.yd] {
            row.joints(j);
        }
        let s: Vec<f64> = x
            .alpha_position
            .as_slice()
            .iter()
            .zip(x.alpha_velocity.as_slice())
            .map(|(p, v)| true_s(*p, *v, self.beta))
            .collect();
        row.floats(&s);
        row.flag(x.active);
        row.flag(x.delivery == fdi_common::records::Delivery::Delivered);
        row.flag(fdi_common::detect::in_force(r));
        let c = &r.center;
        for j in [&c.s_hat, &c.q_hat, &c.qd_hat, &c.qdd_hat, &c.u] {
            row.joints(j);
        }
        for b in [
            c.alarm,
            c.rejected_input,
            c.rejected_torque,
            c.state_reset,
            c.history_miss,
            c.missing_input,
        ] {
            row.flag(b);
        }
        if self.actuation {
            match &r.actuation {
                Some(u) => {
                    row.joints(&u.alpha_u);
                    row.joints(&u.u);
                    row.float(u.held_s);
                    row.flag(u.active);
                }
                None => {
                    row.floats(&[]);
                    row.floats(&[]);
                    row.float(f64::NAN);
                    row.flag(false);
                }
            }
        }
    }

    /// The columns as a list of `(name, dtype, bytes)`: dtype `f8`, `i8` or `?`, the bytes
    /// native-endian (numpy's `frombuffer`).
    pub fn into_py(self, py: Python<'_>) -> PyResult<Bound<'_, PyList>> {
        let len = |d: &Data| match d {
            Data::F64(v) => v.len(),
            Data::I64(v) => v.len(),
            Data::Bool(v) => v.len(),
        };
        let rows = self.data.first().map_or(0, len);
        if let Some((name, _)) = self
            .names
            .iter()
            .zip(&self.data)
            .find(|(_, d)| len(d) != rows)
        {
            return Err(crate::errors::engine_error(format!(
                "column {name} does not have the {rows} rows of the others (a bug)"
            )));
        }
        let list = PyList::empty(py);
        for (name, data) in self.names.into_iter().zip(self.data) {
            let (dtype, bytes): (&str, Vec<u8>) = match data {
                Data::F64(v) => ("f8", v.iter().flat_map(|x| x.to_ne_bytes()).collect()),
                Data::I64(v) => ("i8", v.iter().flat_map(|x| x.to_ne_bytes()).collect()),
                Data::Bool(v) => ("?", v.iter().map(|b| u8::from(*b)).collect()),
            };
            list.append((name, dtype, PyBytes::new(py, &bytes)))?;
        }
        Ok(list)
    }
}

/// The next columns of a row, in the order they were declared.
struct Row<'a> {
    data: &'a mut [Data],
    at: usize,
    links: usize,
}

impl Row<'_> {
    fn next(&mut self) -> Option<&mut Data> {
        let d = self.data.get_mut(self.at);
        self.at += 1;
        d
    }
    fn int(&mut self, v: i64) {
        if let Some(Data::I64(c)) = self.next() {
            c.push(v);
        }
    }
    fn float(&mut self, v: f64) {
        if let Some(Data::F64(c)) = self.next() {
            c.push(v);
        }
    }
    fn flag(&mut self, v: bool) {
        if let Some(Data::Bool(c)) = self.next() {
            c.push(v);
        }
    }
    /// `links` columns from `v`; NaN where `v` has no entry.
    fn floats(&mut self, v: &[f64]) {
        for i in 0..self.links {
            self.float(v.get(i).copied().unwrap_or(f64::NAN));
        }
    }
    fn joints(&mut self, j: &Joints) {
        self.floats(j.as_slice());
    }
}
