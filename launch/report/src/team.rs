//! Reports of teams: which robots get their own figures, and the figure of the whole team.
//!
//! A robot's figures are six (PNG and SVG each); a team of 64 made 768 files and most of the
//! report's time. Teams of more than [`HANDFUL`] robots lead with the team figure (every robot's
//! position error on one plot) and the RMSE table of `report.md`; the per-robot figures are
//! drawn on demand (`fdi-launch report RUN_DIR --robots 3,7`).

use std::collections::BTreeSet;
use std::str::FromStr;

use crate::plot::{Figure, Line, Panel, PanelKind, PALETTE};

/// The largest team whose robots all get their own figures unless told otherwise; a larger
/// team gets the team figure instead.
pub const HANDFUL: usize = 8;

/// Buckets per robot of the team figure (each gives its minimum and maximum): fewer than a
/// robot's own figures, as the team figure holds every robot.
pub const TEAM_BUCKETS: u64 = 400;

/// Which robots get their own figures.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub enum PerRobot {
    /// Every robot of a team of at most [`HANDFUL`], none of a larger one.
    #[default]
    Auto,
    /// Every robot (`--robots all`).
    All,
    /// These robots (`--robots 3,7`).
    Only(BTreeSet<u32>),
}

impl FromStr for PerRobot {
    type Err = String;

    /// `all`, or robot ids separated by commas (`3,7`).
    fn from_str(s: &str) -> Result<Self, String> {
        if s.trim() == "all" {
            return Ok(Self::All);
        }
        let ids = s
            .split(',')
            .map(|p| {
                p.trim().parse::<u32>().map_err(|_| {
                    format!(
                        "`{}` is not a robot id: give `all` or ids separated by commas (`3,7`)",
                        p.trim()
                    )
                })
            })
            .collect::<Result<BTreeSet<u32>, String>>()?;
        Ok(Self::Only(ids))
    }
}

impl PerRobot {
    /// The robots of `team` (ids of the run) that get their own figures; an id that is not a
    /// robot of the run is an error naming the run's robots.
    pub fn robots(&self, team: &[u32]) -> Result<BTreeSet<u32>, String> {
        match self {
            Self::Auto if team.len() <= HANDFUL => Ok(team.iter().copied().collect()),
            Self::Auto => Ok(BTreeSet::new()),
            Self::All => Ok(team.iter().copied().collect()),
            Self::Only(ids) => {
                let unknown: Vec<String> = ids
                    .iter()
                    .filter(|id| !team.contains(id))
                    .map(u32::to_string)
                    .collect();
                if unknown.is_empty() {
                    Ok(ids.clone())
                } else {
                    Err(format!(
                        "--robots: {} {} not a robot of the run (its robots: {})",
                        unknown.join(", "),
                        if unknown.len() == 1 { "is" } else { "are" },
                        describe_ids(team)
                    ))
                }
            }
        }
    }
}

/// `1–64` for consecutive ids, else the ids listed.
pub fn describe_ids(ids: &[u32]) -> String {
    let mut sorted = ids.to_vec();
    sorted.sort_unstable();
    match sorted.as_slice() {
        [] => "none".into(),
        [one] => one.to_string(),
        [first, .., last] if u64::from(*last) - u64::from(*first) + 1 == sorted.len() as u64 => {
            format!("{first}–{last}")
        }
        _ => sorted
            .iter()
            .map(u32::to_string)
            .collect::<Vec<_>>()
            .join(", "),
    }
}

/// Whether a team of `n` robots gets the team figure.
pub fn has_team_figure(n: usize) -> bool {
    n > HANDFUL
}

/// Light grey of the team's robots in the team figure; the robot with the largest RMSE is
/// drawn over them in the palette's first colour.
const TEAM_GREY: plotters::style::RGBColor = plotters::style::RGBColor(170, 170, 170);

/// The team figure: every robot's `‖q_d − q‖` (envelope points per robot, `(id, points)`) on
/// one panel, the robot `worst` (largest RMSE, `worst_rmse` rad) drawn over the others.
pub fn team_figure(
    robots: Vec<(u32, Vec<(f64, f64)>)>,
    worst: Option<(u32, f64)>,
    x_range: (f64, f64),
    partial: &str,
) -> Figure {
    let n = robots.len();
    let mut lines = vec![Line {
        label: format!("each of the {n} robots"),
        color: TEAM_GREY,
        points: Vec::new(),
        keep: false,
        dashed: false,
    }];
    let mut top = None;
    for (id, points) in robots {
        if worst.is_some_and(|(w, _)| w == id) {
            top = Some(points);
            continue;
        }
        lines.push(Line {
            label: String::new(),
            color: TEAM_GREY,
            points,
            keep: false,
            dashed: false,
        });
    }
    if let (Some(points), Some((id, rmse))) = (top, worst) {
        lines.push(Line {
            label: format!("robot {id}: largest RMSE ({rmse:.4} rad)"),
            color: PALETTE[0],
            points,
            // Never clipped: in a large team its points are a small share of the panel's, and
            // the robust range would cut the one curve the figure is meant to show.
            keep: true,
            dashed: false,
        });
    }
    Figure {
        title: format!("Team of {n} robots: position error of every robot{partial}"),
        x_label: "t (s)".into(),
        x_range,
        markers: Vec::new(),
        marker_label: String::new(),
        panels: vec![Panel {
            title: "‖q_d − q‖ (true q), every robot".into(),
            y_label: "rad".into(),
            kind: PanelKind::Lines(lines),
            guides: Vec::new(),
        }],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robots_are_chosen_by_team_size_or_by_name_and_an_unknown_id_is_refused() {
        let four: Vec<u32> = (1..=4).collect();
        let many: Vec<u32> = (1..=64).collect();
        assert_eq!(
            PerRobot::Auto.robots(&four),
            Ok(four.iter().copied().collect())
        );
        assert_eq!(PerRobot::Auto.robots(&many), Ok(BTreeSet::new()));
        assert_eq!(PerRobot::All.robots(&many).map(|s| s.len()), Ok(64));
        let some: PerRobot = "3, 7".parse().expect("ids");
        assert_eq!(some.robots(&many), Ok(BTreeSet::from([3, 7])));
        let e = "3,70,99".parse::<PerRobot>().expect("ids").robots(&many);
        assert_eq!(
            e,
            Err("--robots: 70, 99 are not a robot of the run (its robots: 1–64)".into())
        );
        assert!("3,x"
            .parse::<PerRobot>()
            .is_err_and(|e| e.contains("`x` is not a robot id")));
        assert_eq!("all".parse::<PerRobot>(), Ok(PerRobot::All));
        assert_eq!(describe_ids(&[1, 2, 5]), "1, 2, 5");
        assert!(!has_team_figure(HANDFUL) && has_team_figure(HANDFUL + 1));
    }
}
