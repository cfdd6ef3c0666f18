//! Layouts of a run's figures for the viewers (`fdi-launch layout`): the paper's Figs. 3–6 —
//! position and velocity errors with the paper's bounds, `Ŝ` against the true `S`, alarms and
//! attacks, torques — one tab each, one plot per robot, one series per joint, made for the
//! robots of a scenario (their ids and joint counts), as a Foxglove layout (JSON) or a
//! PlotJuggler one (XML). One description of the figures ([`figures`]), two renderings.
//!
//! The paths name the topics and fields of [`fdi_report::topics`] (the live view's and the MCAP
//! export's); the shipped `examples/live/paper-figures.*` are what this makes for the paper's
//! scenario, and the tests check every path of both against the topics.

use std::fmt::Write as _;

use fdi_report::report::{PAPER_POSITION_BOUND_RAD, PAPER_VELOCITY_BOUND_RAD_S};
use serde::Serialize;

/// One robot of a run: its id and number of joints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Robot {
    pub id: u32,
    pub joints: usize,
}

/// The robots of `scenario`, in id order.
pub fn robots(scenario: &fdi_common::scenario::Scenario) -> Vec<Robot> {
    scenario
        .agent_dofs()
        .into_iter()
        .map(|(id, joints)| Robot { id, joints })
        .collect()
}

/// A field of a robot's topic: `/agent<id>/<topic>` and the field, an element of an array field
/// when `index` is set.
#[derive(Debug, Clone, PartialEq)]
pub struct Field {
    pub agent: u32,
    pub topic: &'static str,
    pub field: &'static str,
    pub index: Option<usize>,
}

impl Field {
    /// The path with `sep` between the topic and the field: `.` for Foxglove's message paths,
    /// `/` for PlotJuggler's series.
    pub fn path(&self, sep: char) -> String {
        let index = self.index.map_or(String::new(), |i| format!("[{i}]"));
        format!(
            "/agent{}/{}{sep}{}{index}",
            self.agent, self.topic, self.field
        )
    }
}

/// One series of a plot: a field, or a constant at a bound of the paper (drawn against the
/// field it bounds).
#[derive(Debug, Clone, PartialEq)]
pub enum Series {
    Field {
        field: Field,
        label: String,
    },
    Bound {
        value: f64,
        of: Field,
        what: &'static str,
    },
}

/// One plot: a robot's figure in one tab.
#[derive(Debug, Clone, PartialEq)]
pub struct Plot {
    pub title: String,
    pub series: Vec<Series>,
}

/// One tab: a figure of every robot.
#[derive(Debug, Clone, PartialEq)]
pub struct Tab {
    pub title: &'static str,
    pub plots: Vec<Plot>,
}

/// The figures of `robots`: five tabs of one plot per robot.
pub fn figures(robots: &[Robot]) -> Vec<Tab> {
    let per_robot = |title: &'static str, plot: &dyn Fn(Robot) -> Plot| Tab {
        title,
        plots: robots.iter().map(|r| plot(*r)).collect(),
    };
    vec![
        per_robot("Position error (Figs. 3a, 4, 6a)", &|r| {
            let (id, bound) = (r.id, PAPER_POSITION_BOUND_RAD);
            let title = format!("Robot {id}: position error q_d - q, rad (paper: ±{bound})");
            error_plot(r, title, "e_rad", "position", bound)
        }),
        // The paper states the velocity bound for robot 1.
        per_robot("Velocity error (Fig. 3b)", &|r| {
            let (id, bound) = (r.id, PAPER_VELOCITY_BOUND_RAD_S);
            let title = format!("Robot {id}: velocity error, rad/s (paper, robot 1: ±{bound})");
            error_plot(r, title, "e_dot_rad_s", "velocity", bound)
        }),
        per_robot("Attack estimate (Fig. 5)", &|r| {
            two_per_joint(
                format!("Robot {}: Ŝ against the true S, rad/s", r.id),
                joint_series(r, "estimate", "s_hat_rad_s", "Ŝ link"),
                joint_series(r, "attack", "s_true_rad_s", "S link"),
            )
        }),
        per_robot("Alarms and attacks", &|r| Plot {
            title: format!("Robot {}: ‖Ŝ‖ alarm, attack in force", r.id),
            series: [
                ("detectors", "s_hat_norm", "‖Ŝ‖ (held)"),
                ("detectors", "s_hat_norm_threshold", "threshold"),
                ("alarm", "alarm", "alarm"),
                ("detectors", "in_force", "attack in force"),
            ]
            .into_iter()
            .map(|(topic, field, label)| Series::Field {
                field: Field {
                    agent: r.id,
                    topic,
                    field,
                    index: None,
                },
                label: label.into(),
            })
            .collect(),
        }),
        per_robot("Torques", &|r| {
            two_per_joint(
                format!("Robot {}: torque sent and applied, N·m", r.id),
                joint_series(r, "torque/sent", "u_nm", "sent link"),
                joint_series(r, "torque/applied", "u_nm", "applied link"),
            )
        }),
    ]
}

/// A plot of two fields per joint: every joint's `first`, then every joint's `second`.
fn two_per_joint(title: String, first: Vec<Series>, second: Vec<Series>) -> Plot {
    Plot {
        title,
        series: [first, second].concat(),
    }
}

/// `field[j]` of `topic` for every joint `j` of `r`, labelled `<label> <j + 1>`.
fn joint_series(r: Robot, topic: &'static str, field: &'static str, label: &str) -> Vec<Series> {
    (0..r.joints)
        .map(|j| Series::Field {
            field: Field {
                agent: r.id,
                topic,
                field,
                index: Some(j),
            },
            label: format!("{label} {}", j + 1),
        })
        .collect()
}

/// `title`: a tracking error `field` of every joint of `r` with the paper's bound `±bound` on
/// `what` (position or velocity).
fn error_plot(
    r: Robot,
    title: String,
    field: &'static str,
    what: &'static str,
    bound: f64,
) -> Plot {
    let mut series = joint_series(r, "tracking_error", field, "link");
    let of = Field {
        agent: r.id,
        topic: "tracking_error",
        field,
        index: Some(0),
    };
    for value in [bound, -bound] {
        series.push(Series::Bound {
            value,
            of: of.clone(),
            what,
        });
    }
    Plot { title, series }
}

/// The colours of the series of a plot, in turn (matplotlib's; its grey is the bounds').
const COLOURS: [&str; 9] = [
    "#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#bcbd22",
    "#17becf",
];
const BOUND_COLOUR: &str = "#7f7f7f";

impl Plot {
    /// Each series with its colour: the field series take [`COLOURS`] in turn, the bounds grey.
    fn coloured(&self) -> impl Iterator<Item = (&Series, &'static str)> {
        let mut fields = 0;
        self.series.iter().map(move |s| match s {
            Series::Field { .. } => {
                fields += 1;
                (s, COLOURS[(fields - 1) % COLOURS.len()])
            }
            Series::Bound { .. } => (s, BOUND_COLOUR),
        })
    }
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
struct FoxglovePath {
    value: String,
    enabled: bool,
    timestamp_method: &'static str,
    label: String,
    color: &'static str,
}

#[derive(Serialize)]
#[serde(rename_all = "camelCase")]
struct FoxglovePlot {
    title: String,
    paths: Vec<FoxglovePath>,
    show_x_axis_labels: bool,
    show_y_axis_labels: bool,
    show_legend: bool,
    legend_display: &'static str,
    show_plot_values_in_legend: bool,
    is_synced: bool,
    x_axis_val: &'static str,
    sidebar_dimension: u32,
}

/// The layout of `tabs` for Foxglove (*Layouts* → *Import from file*): a plot panel per robot
/// and tab, the robots of a tab split in halves, rows then columns.
pub fn foxglove(tabs: &[Tab]) -> serde_json::Value {
    let mut config = serde_json::Map::new();
    let mut tab_configs = Vec::new();
    let mut n = 0;
    for tab in tabs {
        let mut ids = Vec::new();
        for plot in &tab.plots {
            n += 1;
            let id = format!("Plot!fdi{n}");
            let paths = plot
                .coloured()
                .map(|(s, color)| {
                    let (value, label) = match s {
                        Series::Field { field, label } => (field.path('.'), label.clone()),
                        Series::Bound { value, .. } => (value.to_string(), "paper bound".into()),
                    };
                    FoxglovePath {
                        value,
                        enabled: true,
                        timestamp_method: "receiveTime",
                        label,
                        color,
                    }
                })
                .collect();
            let panel = FoxglovePlot {
                title: plot.title.clone(),
                paths,
                show_x_axis_labels: true,
                show_y_axis_labels: true,
                show_legend: true,
                legend_display: "floating",
                show_plot_values_in_legend: false,
                is_synced: true,
                x_axis_val: "timestamp",
                sidebar_dimension: 240,
            };
            config.insert(id.clone(), serde_json::json!(panel));
            ids.push(id);
        }
        tab_configs.push(serde_json::json!({
            "title": tab.title,
            "layout": split(&ids, "row"),
        }));
    }
    config.insert(
        "Tab!fdi".into(),
        serde_json::json!({ "activeTabIdx": 0, "tabs": tab_configs }),
    );
    serde_json::json!({
        "configById": config,
        "globalVariables": {},
        "userNodes": {},
        "playbackConfig": { "speed": 1.0 },
        "layout": "Tab!fdi",
    })
}

/// Foxglove's mosaic of `ids`: one panel, or the first half and the second split along
/// `direction` (the halves along the other direction).
fn split(ids: &[String], direction: &'static str) -> serde_json::Value {
    match ids {
        [] => serde_json::Value::Null,
        [one] => serde_json::json!(one),
        _ => {
            let half = ids.len().div_ceil(2);
            let other = if direction == "row" { "column" } else { "row" };
            let percentage = 100.0 * half as f64 / ids.len() as f64;
            serde_json::json!({
                "first": split(&ids[..half], other),
                "second": split(&ids[half..], other),
                "direction": direction,
                "splitPercentage": percentage,
            })
        }
    }
}

/// The layout of `tabs` for PlotJuggler (*File* → *Load layout*, after loading the run's MCAP
/// or connecting to the live view): a tab of stacked plots per figure; the bounds are custom
/// series, constants made from the error they bound.
pub fn plotjuggler(tabs: &[Tab]) -> String {
    let mut xml = String::from("<?xml version='1.0' encoding='UTF-8'?>\n<root>\n");
    xml += " <tabbed_widget name=\"Main Window\" parent=\"main_window\">\n";
    let mut bounds = Vec::new();
    for tab in tabs {
        let count = tab.plots.len();
        let size = format!("{:.6}", 1.0 / count.max(1) as f64);
        let sizes = vec![size; count].join(";");
        let _ = writeln!(
            xml,
            "  <Tab tab_name=\"{}\" containers=\"1\">\n   <Container>\n    <DockSplitter \
             orientation=\"-\" sizes=\"{sizes}\" count=\"{count}\">",
            escape(tab.title)
        );
        for plot in &tab.plots {
            let _ = writeln!(
                xml,
                "     <DockArea name=\"{}\">\n      <plot mode=\"TimeSeries\" flip_x=\"false\" \
                 flip_y=\"false\" style=\"Lines\">\n       <range left=\"0\" right=\"1\" \
                 top=\"1\" bottom=\"-1\"/>\n       <limitY/>",
                escape(&plot.title)
            );
            for (s, colour) in plot.coloured() {
                let name = match s {
                    Series::Field { field, .. } => field.path('/'),
                    Series::Bound { value, of, what } => {
                        let name = format!("paper bound: robot {} {what} {value:+}", of.agent);
                        bounds.push((name.clone(), *value, of.path('/')));
                        name
                    }
                };
                let _ = writeln!(
                    xml,
                    "       <curve name=\"{}\" color=\"{colour}\"/>",
                    escape(&name)
                );
            }
            xml += "      </plot>\n     </DockArea>\n";
        }
        xml += "    </DockSplitter>\n   </Container>\n  </Tab>\n";
    }
    xml += "  <currentTabIndex index=\"0\"/>\n </tabbed_widget>\n";
    xml += " <use_relative_time_offset enabled=\"0\"/>\n";
    xml += " <!-- The paper's bounds: constant series made from the error they bound. -->\n";
    xml += " <customMathEquations>\n";
    for (name, value, source) in bounds {
        let _ = writeln!(
            xml,
            "  <snippet name=\"{}\">\n   <global></global>\n   <function>return {value}</function>\n   \
             <linked_source>{}</linked_source>\n  </snippet>",
            escape(&name),
            escape(&source)
        );
    }
    xml += " </customMathEquations>\n</root>\n";
    xml
}

/// `text` as XML attribute or element text.
fn escape(text: &str) -> String {
    text.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_robot_gets_a_plot_per_tab_and_a_series_per_joint() {
        let robots = [
            Robot { id: 1, joints: 2 },
            Robot { id: 9, joints: 7 },
            Robot { id: 3, joints: 2 },
        ];
        let tabs = figures(&robots);
        assert_eq!(tabs.len(), 5);
        for tab in &tabs {
            assert_eq!(tab.plots.len(), 3, "{}", tab.title);
        }
        let fields = |p: &Plot| {
            p.series
                .iter()
                .filter(|s| matches!(s, Series::Field { .. }))
                .count()
        };
        // Errors: one series per joint and the two bounds; Ŝ and S, sent and applied: two per
        // joint.
        assert_eq!(fields(&tabs[0].plots[1]), 7);
        assert_eq!(tabs[0].plots[1].series.len(), 9);
        assert_eq!(fields(&tabs[2].plots[1]), 14);
        assert_eq!(fields(&tabs[4].plots[0]), 4);
        let Series::Field { field, .. } = &tabs[2].plots[1].series[13] else {
            panic!("a field")
        };
        assert_eq!(field.path('.'), "/agent9/attack.s_true_rad_s[6]");
        assert_eq!(field.path('/'), "/agent9/attack/s_true_rad_s[6]");
        // Three robots in a tab: the first two in a column, the third beside them.
        let layout = foxglove(&tabs);
        let first = &layout["configById"]["Tab!fdi"]["tabs"][0]["layout"];
        assert_eq!(first["direction"], "row");
        assert_eq!(first["first"]["direction"], "column");
        assert_eq!(first["second"], "Plot!fdi3");
        // Every plot of every tab is a panel, and names a panel that exists.
        assert_eq!(layout["configById"].as_object().map(|c| c.len()), Some(16));
        let xml = plotjuggler(&tabs);
        assert_eq!(xml.matches("<DockArea ").count(), 15);
        assert_eq!(xml.matches("<snippet ").count(), 12);
        assert!(xml.contains("count=\"3\""), "{xml}");
    }
}
