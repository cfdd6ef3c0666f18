//! Every tick of a run as columns (one row per robot and tick, in the trace digest's order):
//! the tick table of `fdi_report::columns`, whose names the CSV export's files share
//! (docs/traces.md), for numpy arrays and a pandas DataFrame on the Python side.

use std::collections::BTreeMap;

use fdi_common::records::{true_s, Joints, TickRecord};
use fdi_common::scenario::Resolved;
use fdi_common::trajectory::TrajectoryConfig;
use fdi_report::columns;
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
    /// Each robot's trajectory and the `q_d` of its joint count.
    trajectories: BTreeMap<u32, (TrajectoryConfig, DesiredFn)>,
    names: Vec<String>,
    data: Vec<Data>,
    scratch: Vec<f64>,
    /// The first column a row did not fill as declared (its index), or the row's length when
    /// it filled another number of columns: a bug, reported by [`Columns::into_py`].
    misfit: Option<usize>,
}

impl Columns {
    /// The columns of `resolved`'s records; `actuation`: its records carry the torque path's.
    pub fn new(resolved: &Resolved, actuation: bool) -> Self {
        // A column per joint of the largest arm; a smaller arm's other columns are NaN.
        let s = &resolved.scenario;
        let links = s.joint_counts().last().copied().unwrap_or(0);
        let mut c = Self {
            links,
            beta: s.controller.beta,
            actuation,
            trajectories: (s.agents.iter())
                .filter_map(|a| {
                    let n = a.model.dof();
                    let f = fdi_common::with_joint_count!(n, N => desired::<N> as DesiredFn)?;
                    Some((a.id, (a.trajectory.clone(), f)))
                })
                .collect(),
            names: Vec::new(),
            data: Vec::new(),
            scratch: vec![0.0; links],
            misfit: None,
        };
        c.declare();
        c
    }

    /// The columns of the tick table (`fdi_report::columns::tick_table`: the names and types
    /// the CSV export's files share).
    fn declare(&mut self) {
        for (name, ty) in columns::tick_table(self.links, self.actuation) {
            self.names.push(name);
            self.data.push(match ty {
                columns::Type::Int => Data::I64(Vec::new()),
                columns::Type::Flag => Data::Bool(Vec::new()),
                columns::Type::Float | columns::Type::Text => Data::F64(Vec::new()),
            });
        }
    }

    /// Appends the row of one record.
    pub fn push(&mut self, r: &TickRecord) {
        let mut row = Row {
            data: &mut self.data,
            at: 0,
            links: self.links,
            misfit: &mut self.misfit,
        };
        row.int(r.agent.k as i64);
        row.int(i64::from(r.agent.agent));
        row.float(r.agent.t);
        match self.trajectories.get(&r.agent.agent) {
            Some((traj, desired)) => {
                self.scratch.fill(f64::NAN);
                desired(traj, r.agent.t, &mut self.scratch);
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
        row.flag(x.active);
        let s: Vec<f64> = x
            .alpha_position
            .as_slice()
            .iter()
            .zip(x.alpha_velocity.as_slice())
            .map(|(p, v)| true_s(*p, *v, self.beta))
            .collect();
        row.floats(&s);
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
        if row.at != row.data.len() {
            row.misfit.get_or_insert(row.at);
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
        if let Some(at) = self.misfit {
            return Err(crate::errors::engine_error(format!(
                "the tick table's row did not fill column {at} as declared (a bug)"
            )));
        }
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
    misfit: &'a mut Option<usize>,
}

impl Row<'_> {
    fn next(&mut self) -> Option<&mut Data> {
        let d = self.data.get_mut(self.at);
        self.at += 1;
        d
    }
    /// Notes the column just passed as not filled as declared.
    fn misfit(&mut self) {
        let at = self.at - 1;
        self.misfit.get_or_insert(at);
    }
    fn int(&mut self, v: i64) {
        match self.next() {
            Some(Data::I64(c)) => c.push(v),
            _ => self.misfit(),
        }
    }
    fn float(&mut self, v: f64) {
        match self.next() {
            Some(Data::F64(c)) => c.push(v),
            _ => self.misfit(),
        }
    }
    fn flag(&mut self, v: bool) {
        match self.next() {
            Some(Data::Bool(c)) => c.push(v),
            _ => self.misfit(),
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
