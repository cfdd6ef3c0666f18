//! `fdi-launch model FILE.urdf`: what a URDF arm is to fdi-mas (`fdi_common::model::urdf`) —
//! its moving joints in the order of `q`, their limits, the links' masses — and its dynamics at
//! one state: `M(q)`, `V(q, q̇)`, `G(q)` and `F(q̇)`, as text or as one JSON object.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result};
use clap::Args;
use fdi_common::model::urdf::{Chain, Motion, UrdfSpec, GRAVITY};
use nalgebra::{DMatrix, DVector};
use serde_json::json;

/// `fdi-launch model`'s flags.
#[derive(Debug, Args)]
pub struct ModelArgs {
    /// The URDF file.
    pub file: PathBuf,
    /// Hold a joint at a value (rad or m), as a fixed joint: `--lock finger=0.02`; repeat it.
    #[arg(long = "lock", value_name = "JOINT=VALUE", value_parser = lock_of)]
    pub locks: Vec<(String, f64)>,
    /// The link the arm is mounted by (default: the file's root link).
    #[arg(long)]
    pub root: Option<String>,
    /// The last link of the arm: every moving joint must lie between the root and it.
    #[arg(long)]
    pub tip: Option<String>,
    /// The joint positions, in the order of the joints, separated by commas (default: zeros).
    #[arg(long, value_name = "V1,V2,…", value_parser = values_of, allow_hyphen_values = true)]
    pub q: Option<Values>,
    /// The joint velocities, as `--q` (default: zeros).
    #[arg(long, value_name = "V1,V2,…", value_parser = values_of, allow_hyphen_values = true)]
    pub qd: Option<Values>,
    /// Gravity in the root link's frame, m/s², as `x,y,z`.
    #[arg(long, value_name = "X,Y,Z", value_parser = values_of, allow_hyphen_values = true)]
    pub gravity: Option<Values>,
    /// Print one JSON object: `joints` (names), `inertia`, `coriolis` (lists of rows),
    /// `gravity`, `friction` (lists), `inertia_positive_definite`, with the limits, masses and
    /// the state.
    #[arg(long)]
    pub json: bool,
}

/// Numbers given on the command line, separated by commas.
#[derive(Debug, Clone, PartialEq)]
pub struct Values(pub Vec<f64>);

fn values_of(s: &str) -> Result<Values, String> {
    s.split(',')
        .map(|v| {
            let x: f64 = v
                .trim()
                .parse()
                .map_err(|_| format!("`{v}` is not a number"))?;
            if x.is_finite() {
                Ok(x)
            } else {
                Err(format!("`{v}` is not finite"))
            }
        })
        .collect::<Result<_, _>>()
        .map(Values)
}

fn lock_of(s: &str) -> Result<(String, f64), String> {
    let (joint, value) = s
        .split_once('=')
        .ok_or_else(|| format!("`{s}`: a lock is JOINT=VALUE"))?;
    let v: f64 = value
        .trim()
        .parse()
        .map_err(|_| format!("`{s}`: `{value}` is not a number"))?;
    Ok((joint.trim().to_string(), v))
}

/// `model`: the arm and its terms at the state asked for.
pub fn model(args: &ModelArgs) -> Result<ExitCode> {
    let mut spec = UrdfSpec::new(&args.file);
    spec.root.clone_from(&args.root);
    spec.tip.clone_from(&args.tip);
    spec.lock = args.locks.iter().cloned().collect();
    spec.gravity = match &args.gravity {
        None => GRAVITY,
        Some(Values(g)) => <[f64; 3]>::try_from(g.as_slice())
            .map_err(|_| anyhow::anyhow!("--gravity: 3 values x,y,z, got {}", g.len()))?,
    };
    let chain = Chain::load(&spec, std::path::Path::new(""))?;
    let n = chain.dof();
    let state = |v: &Option<Values>| v.as_ref().map_or_else(|| vec![0.0; n], |v| v.0.clone());
    let (q, qd) = (state(&args.q), state(&args.qd));
    let terms = chain
        .dynamics(&q, &qd)
        .map_err(anyhow::Error::msg)
        .with_context(|| format!("--q/--qd for {}", args.file.display()))?;
    // The forward dynamics needs M⁻¹: where M is not positive definite the arm has none (a
    // scenario refuses an arm whose M at q = 0 is not).
    let definite = terms.inertia.clone().cholesky().is_some();
    if args.json {
        let rows = |m: &DMatrix<f64>| -> Vec<Vec<f64>> {
            m.row_iter().map(|r| r.iter().copied().collect()).collect()
        };
        let list = |v: &DVector<f64>| -> Vec<f64> { v.iter().copied().collect() };
        let out = json!({
            "robot": chain.name,
            "file": args.file,
            "joints": chain.joint_names(),
            "motions": chain.joints.iter().map(|j| j.motion).collect::<Vec<_>>(),
            "limits": chain.joints.iter().map(|j| j.limits.map(|(lo, hi)| [lo, hi])).collect::<Vec<_>>(),
            "masses": chain.masses.iter().map(|(l, m)| json!({"link": l, "kg": m})).collect::<Vec<_>>(),
            "gravity_vector": spec.gravity,
            "q": q,
            "qd": qd,
            "inertia": rows(&terms.inertia),
            "inertia_positive_definite": definite,
            "coriolis": rows(&terms.coriolis),
            "gravity": list(&terms.gravity),
            "friction": list(&terms.friction),
        });
        println!("{out}");
        return Ok(ExitCode::SUCCESS);
    }
    print!(
        "{}",
        text(&chain, &args.file, (&q, &qd), (&terms, definite))
    );
    Ok(ExitCode::SUCCESS)
}

fn text(
    chain: &Chain,
    file: &std::path::Path,
    (q, qd): (&[f64], &[f64]),
    (terms, definite): (&fdi_common::model::urdf::Dynamics, bool),
) -> String {
    use std::fmt::Write as _;
    let mut out = String::new();
    let n = chain.dof();
    let _ = writeln!(
        out,
        "robot `{}` ({}): {n} moving joint{}, in the order of q",
        chain.name,
        file.display(),
        if n == 1 { "" } else { "s" }
    );
    for (i, j) in chain.joints.iter().enumerate() {
        let unit = match j.motion {
            Motion::Revolute => "rad",
            Motion::Prismatic => "m",
        };
        let limits = j.limits.map_or_else(
            || "no limits".to_string(),
            |(lo, hi)| format!("[{lo}, {hi}] {unit}"),
        );
        let _ = writeln!(
            out,
            "  {:>2}  {:<24} {:<9} {limits}; damping {}, friction {}",
            i + 1,
            j.name,
            format!("{:?}", j.motion).to_lowercase(),
            j.damping,
            j.friction
        );
    }
    let masses: Vec<String> = (chain.masses.iter())
        .map(|(l, m)| format!("{l} {m} kg"))
        .collect();
    // From +0: an empty sum of floats is −0, printed "-0.000000".
    let moving = chain.bodies.iter().fold(0.0, |sum, b| sum + b.mass);
    let _ = writeln!(
        out,
        "links: {}; moving with the joints: {moving:.6} kg",
        masses.join(", ")
    );
    let vector = |v: &[f64]| -> String {
        let cells: Vec<String> = v.iter().map(|&x| six_places(x)).collect();
        format!("[{}]", cells.join(", "))
    };
    let _ = writeln!(out, "at q = {}, q̇ = {}:", vector(q), vector(qd));
    let matrix = |out: &mut String, name: &str, m: &DMatrix<f64>| {
        let _ = writeln!(out, "{name} =");
        for r in m.row_iter() {
            let cells: Vec<String> = r
                .iter()
                .map(|&x| format!("{:>13}", six_places(x)))
                .collect();
            let _ = writeln!(out, "  [{} ]", cells.join(""));
        }
    };
    matrix(&mut out, "M(q)", &terms.inertia);
    matrix(&mut out, "V(q, q̇)", &terms.coriolis);
    let _ = writeln!(out, "G(q) = {}", vector(terms.gravity.as_slice()));
    let _ = writeln!(out, "F(q̇) = {}", vector(terms.friction.as_slice()));
    if !definite {
        let _ = writeln!(
            out,
            "M(q) is not positive definite at this state: the arm has no forward dynamics here \
             (a moving link without mass or inertia?)"
        );
    }
    out
}

/// `x` to six decimal places, without the sign of a value that rounds to zero (`-1e-17` is
/// `0.000000`, not `-0.000000`).
fn six_places(x: f64) -> String {
    let s = format!("{x:.6}");
    match s.strip_prefix('-') {
        Some(rest) if rest.chars().all(|c| c == '0' || c == '.') => rest.to_string(),
        _ => s,
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_value_that_rounds_to_zero_is_printed_without_a_sign() {
        assert_eq!(super::six_places(-1e-17), "0.000000");
        assert_eq!(super::six_places(-0.0), "0.000000");
        assert_eq!(super::six_places(-0.5), "-0.500000");
        assert_eq!(super::six_places(-0.000002), "-0.000002");
    }
}
