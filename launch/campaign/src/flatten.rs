//! A run summary as one row of named cells: every metric of `summary.json`, per robot
//! (`robot<id>.<metric>`, nested keys joined by `.`: `robot1.detectors.chi2.coverage`). Lists
//! of onsets become their count, the number detected, and the mean and largest time to detect
//! (`….onsets.n`, `.detected`, `.mean_time_to_detect_s`, `.max_time_to_detect_s`); the
//! per-onset flags `alarm_on_at_onset` their count of `true` (`….alarm_on_at_onset.n_true`);
//! other lists one cell per element (`.0`, `.1`, …). A value the summary holds as `null` (no
//! detection, no false-alarm rate without attack-free time) is an empty cell, never a number.

use anyhow::Result;
use fdi_common::engine::RunSummary;
use serde_json::Value;

/// One cell of a row.
#[derive(Debug, Clone, PartialEq)]
pub enum Cell {
    Num(f64),
    /// An integer kept exact (a seed near 2⁶³ is not a float).
    Int(i128),
    Text(String),
    Empty,
}

impl Cell {
    pub fn num(&self) -> Option<f64> {
        match self {
            Self::Num(x) if x.is_finite() => Some(*x),
            Self::Int(i) => Some(*i as f64),
            _ => None,
        }
    }

    /// The cell as written in a CSV file: a number in its shortest exact form.
    pub fn csv(&self) -> String {
        match self {
            Self::Num(x) => x.to_string(),
            Self::Int(i) => i.to_string(),
            Self::Text(s) => s.clone(),
            Self::Empty => String::new(),
        }
    }

    pub fn json(&self) -> Value {
        match self {
            Self::Num(x) => serde_json::Number::from_f64(*x).map_or(Value::Null, Value::Number),
            Self::Int(i) => match (u64::try_from(*i), i64::try_from(*i)) {
                (Ok(u), _) => Value::Number(u.into()),
                (_, Ok(i)) => Value::Number(i.into()),
                // Beyond 64 bits (no summary or TOML value is): the digits, exact.
                _ => Value::String(i.to_string()),
            },
            Self::Text(s) => Value::String(s.clone()),
            Self::Empty => Value::Null,
        }
    }
}

/// The cells of a summary, in a stable order.
pub fn flatten(s: &RunSummary) -> Result<Vec<(String, Cell)>> {
    let mut out = vec![
        ("engine".to_string(), Cell::Text(s.engine.clone())),
        ("controller".into(), Cell::Text(s.controller.clone())),
        ("attack".into(), Cell::Text(s.attack.clone())),
        ("agents".into(), Cell::Num(s.agents as f64)),
        ("ticks".into(), Cell::Num(s.ticks as f64)),
        ("planned_ticks".into(), Cell::Num(s.planned_ticks as f64)),
        ("sim_s".into(), Cell::Num(s.sim_s)),
        ("lost_agents".into(), Cell::Num(s.lost_agents.len() as f64)),
        (
            "partial".into(),
            Cell::Text(
                s.partial
                    .as_ref()
                    .map_or(String::new(), |p| p.reason.clone()),
            ),
        ),
        ("trace_digest".into(), Cell::Text(s.trace_digest.clone())),
    ];
    for (id, m) in &s.metrics {
        walk(&format!("robot{id}"), &serde_json::to_value(m)?, &mut out);
    }
    Ok(out)
}

fn walk(name: &str, v: &Value, out: &mut Vec<(String, Cell)>) {
    let key = |k: &str| format!("{name}.{k}");
    match v {
        Value::Null => out.push((name.into(), Cell::Empty)),
        Value::Bool(b) => out.push((name.into(), Cell::Num(f64::from(u8::from(*b))))),
        Value::Number(n) => out.push((name.into(), n.as_f64().map_or(Cell::Empty, Cell::Num))),
        Value::String(s) => out.push((name.into(), Cell::Text(s.clone()))),
        Value::Object(o) => {
            for (k, v) in o {
                match (k.as_str(), v) {
                    ("onsets", Value::Array(a)) => onsets(&key(k), a, out),
                    ("alarm_on_at_onset", Value::Array(a)) => out.push((
                        key("alarm_on_at_onset.n_true"),
                        Cell::Num(a.iter().filter(|x| x.as_bool() == Some(true)).count() as f64),
                    )),
                    _ => walk(&key(k), v, out),
                }
            }
        }
        Value::Array(a) => {
            for (i, v) in a.iter().enumerate() {
                walk(&key(&i.to_string()), v, out);
            }
        }
    }
}

fn onsets(name: &str, a: &[Value], out: &mut Vec<(String, Cell)>) {
    let delays: Vec<f64> = a
        .iter()
        .filter_map(|o| o.get("time_to_detect_s").and_then(Value::as_f64))
        .collect();
    let cell = |x: Option<f64>| x.map_or(Cell::Empty, Cell::Num);
    out.push((format!("{name}.n"), Cell::Num(a.len() as f64)));
    out.push((format!("{name}.detected"), Cell::Num(delays.len() as f64)));
    out.push((
        format!("{name}.mean_time_to_detect_s"),
        cell((!delays.is_empty()).then(|| delays.iter().sum::<f64>() / delays.len() as f64)),
    ));
    out.push((
        format!("{name}.max_time_to_detect_s"),
        cell(delays.iter().copied().reduce(f64::max)),
    ));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nested_values_get_dotted_names_and_nulls_stay_empty() {
        let v: Value = serde_json::json!({
            "rmse_rad": 0.5,
            "diverged_at_s": null,
            "onsets": [{"t_s": 1.0, "time_to_detect_s": 0.5}, {"t_s": 2.0, "time_to_detect_s": null},
                       {"t_s": 3.0, "time_to_detect_s": 1.5}],
            "detectors": {"chi2": {"coverage": 0.25, "alarm_on_at_onset": [true, false, true],
                                   "residual_rms": [1.0, 2.0], "failed": "why"}}
        });
        let mut out = Vec::new();
        walk("robot1", &v, &mut out);
        let get = |k: &str| {
            out.iter()
                .find(|(n, _)| n == k)
                .map(|(_, c)| c.clone())
                .unwrap_or_else(|| panic!("no column {k} in {out:?}"))
        };
        assert_eq!(get("robot1.rmse_rad"), Cell::Num(0.5));
        assert_eq!(get("robot1.diverged_at_s"), Cell::Empty);
        assert_eq!(get("robot1.onsets.n"), Cell::Num(3.0));
        assert_eq!(get("robot1.onsets.detected"), Cell::Num(2.0));
        assert_eq!(get("robot1.onsets.mean_time_to_detect_s"), Cell::Num(1.0));
        assert_eq!(get("robot1.onsets.max_time_to_detect_s"), Cell::Num(1.5));
        assert_eq!(get("robot1.detectors.chi2.coverage"), Cell::Num(0.25));
        assert_eq!(
            get("robot1.detectors.chi2.alarm_on_at_onset.n_true"),
            Cell::Num(2.0)
        );
        assert_eq!(get("robot1.detectors.chi2.residual_rms.1"), Cell::Num(2.0));
        assert_eq!(
            get("robot1.detectors.chi2.failed"),
            Cell::Text("why".into())
        );
        let mut none = Vec::new();
        onsets("x", &[], &mut none);
        assert_eq!(none[2].1, Cell::Empty);
    }
}
