//! The URDF files a scenario's models name (`model = { kind = "urdf", path = … }`), read before
//! the scenario is: each file once, relative to the scenario file's folder, into the
//! scenario's `urdf_files` (its texts by `path` as written), and each model given its file's
//! text. A scenario a run wrote holds every text in its `urdf_files`, so it reads no file.

use std::path::Path;

use crate::problem::Problem;

/// The scenario's table of URDF texts by path.
pub const KEY: &str = "urdf_files";
/// The key of a model's table that carries its file's text while the scenario is read.
pub const TEXT_KEY: &str = "urdf_text";

/// Gives each model of kind `urdf` in `root` (`defaults.model`, `agents[i].model`) its file's
/// text: from `root`'s [`KEY`] table when it holds the path, else read from `base_dir` (and
/// put in that table). Without `base_dir` no file is read: a path the table lacks is a
/// problem. Returns the problems (at `<model>.path`) and the models they leave without a text
/// (whose reading would only repeat them).
pub fn read_into(root: &mut toml::Table, base_dir: Option<&Path>) -> (Vec<Problem>, Vec<String>) {
    let mut problems = Vec::new();
    let mut unread = Vec::new();
    let mut texts = match root.get(KEY) {
        Some(toml::Value::Table(t)) => t.clone(),
        _ => toml::Table::new(),
    };
    let mut read_any = false;
    for (at, model) in models(root) {
        if model.get("kind").and_then(toml::Value::as_str) != Some("urdf") {
            continue;
        }
        if model.contains_key(TEXT_KEY) {
            problems.push(Problem {
                path: format!("{at}.{TEXT_KEY}"),
                message: format!(
                    "is not a key of a model: the file's text is read from `path` (or taken \
                     from the scenario's `{KEY}`)"
                ),
            });
            model.remove(TEXT_KEY);
            unread.push(at);
            continue;
        }
        // A `path` that is no string is the reading's problem.
        let Some(path) = model.get("path").and_then(toml::Value::as_str) else {
            continue;
        };
        let text = match (texts.get(path), base_dir) {
            (Some(toml::Value::String(t)), _) => Ok(t.clone()),
            (Some(_), _) => Err(format!("`{KEY}.\"{path}\"` is not a string")),
            (None, Some(dir)) => crate::files::read_limited(&dir.join(path)),
            (None, None) => Err(format!(
                "`{path}` is not in the scenario's `{KEY}`, and a scenario read without its \
                 folder reads no file"
            )),
        };
        match text {
            Ok(t) => {
                if !texts.contains_key(path) {
                    texts.insert(path.to_owned(), toml::Value::String(t.clone()));
                    read_any = true;
                }
                model.insert(TEXT_KEY.into(), toml::Value::String(t));
            }
            Err(why) => {
                problems.push(Problem {
                    path: format!("{at}.path"),
                    message: why,
                });
                unread.push(at);
            }
        }
    }
    if read_any {
        root.insert(KEY.into(), toml::Value::Table(texts));
    }
    (problems, unread)
}

/// The model tables of `root` with their paths: `defaults.model`, then `agents[i].model`.
fn models(root: &mut toml::Table) -> Vec<(String, &mut toml::Table)> {
    let mut out = Vec::new();
    let (mut defaults, mut agents) = (None, None);
    for (k, v) in root.iter_mut() {
        match k.as_str() {
            "defaults" => defaults = Some(v),
            "agents" => agents = Some(v),
            _ => {}
        }
    }
    if let Some(toml::Value::Table(d)) = defaults {
        if let Some(toml::Value::Table(m)) = d.get_mut("model") {
            out.push(("defaults.model".to_owned(), m));
        }
    }
    if let Some(toml::Value::Array(agents)) = agents {
        for (i, a) in agents.iter_mut().enumerate() {
            if let toml::Value::Table(a) = a {
                if let Some(toml::Value::Table(m)) = a.get_mut("model") {
                    out.push((format!("agents[{i}].model"), m));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn table(text: &str) -> toml::Table {
        toml::from_str(text).expect("TOML")
    }

    #[test]
    fn each_file_is_read_once_and_every_model_gets_its_text() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join("arm.urdf"), "<robot name=\"a\"/>").expect("write");
        let mut root = table(
            r#"
            defaults = { model = { kind = "urdf", path = "arm.urdf" } }
            [[agents]]
            id = 1
            [[agents]]
            id = 2
            model = { kind = "urdf", path = "arm.urdf", tip = "x" }
            [[agents]]
            id = 3
            model = { kind = "two-link" }
            "#,
        );
        let (problems, unread) = read_into(&mut root, Some(dir.path()));
        assert!(problems.is_empty() && unread.is_empty(), "{problems:?}");
        let texts = root[KEY].as_table().expect("urdf_files");
        assert_eq!(texts.len(), 1);
        assert_eq!(texts["arm.urdf"].as_str(), Some("<robot name=\"a\"/>"));
        assert_eq!(
            root["defaults"]["model"][TEXT_KEY].as_str(),
            Some("<robot name=\"a\"/>")
        );
        let agents = root["agents"].as_array().expect("agents");
        assert!(agents[1]["model"].get(TEXT_KEY).is_some());
        assert!(
            agents[2]["model"].get(TEXT_KEY).is_none(),
            "not a URDF model"
        );
        // Read again without its folder, the scenario finds its texts in `urdf_files`.
        let mut again = root.clone();
        for (_, m) in models(&mut again) {
            m.remove(TEXT_KEY);
        }
        let (problems, _) = read_into(&mut again, None);
        assert!(problems.is_empty(), "{problems:?}");
        assert_eq!(again, root);
    }

    #[test]
    fn a_missing_file_a_file_read_without_a_folder_and_a_text_in_the_model_are_named() {
        let dir = tempfile::tempdir().expect("tempdir");
        let text = r#"
            [[agents]]
            id = 1
            model = { kind = "urdf", path = "nowhere.urdf" }
            [[agents]]
            id = 2
            model = { kind = "urdf", path = "x.urdf", urdf_text = "<robot/>" }
            "#;
        let (problems, unread) = read_into(&mut table(text), Some(dir.path()));
        assert_eq!(unread, ["agents[0].model", "agents[1].model"]);
        assert_eq!(problems[0].path, "agents[0].model.path");
        assert!(problems[0].message.contains("nowhere.urdf"), "{problems:?}");
        assert_eq!(problems[1].path, "agents[1].model.urdf_text");
        let (problems, _) = read_into(&mut table(text), None);
        assert!(
            problems[0].message.contains("reads no file"),
            "{problems:?}"
        );
    }

    /// The repository's folder.
    #[cfg(feature = "urdf")]
    fn repo() -> std::path::PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .parent()
            .expect("the repository")
            .to_path_buf()
    }

    #[cfg(feature = "urdf")]
    #[test]
    fn a_scenario_s_urdf_arm_is_the_hand_written_one_and_its_run_s_scenario_carries_it() {
        use crate::model::{ModelConfig, TwoLinkParams, Vector};
        let r = crate::scenario::load_file(&repo().join("scenarios/paper-urdf.toml"))
            .expect("scenarios/paper-urdf.toml");
        let urdf = r.scenario.agents[0].model.clone();
        assert!(matches!(urdf, ModelConfig::Urdf(_)), "{urdf:?}");
        assert_eq!(urdf.dof(), 2);
        let ours = urdf.build::<2>().expect("two joints");
        let paper = ModelConfig::TwoLink(TwoLinkParams::PAPER)
            .build::<2>()
            .expect("two links");
        let (q, qd) = (Vector::<2>::new(0.3, -1.1), Vector::<2>::new(0.7, 0.2));
        let close = |a: &[f64], b: &[f64]| {
            let scale = b.iter().fold(1.0_f64, |m, x| m.max(x.abs()));
            a.iter().zip(b).all(|(x, y)| (x - y).abs() <= 1e-12 * scale)
        };
        assert!(close(
            ours.inertia(&q).as_slice(),
            paper.inertia(&q).as_slice()
        ));
        assert!(close(
            ours.coriolis(&q, &qd).as_slice(),
            paper.coriolis(&q, &qd).as_slice()
        ));
        assert!(close(
            ours.gravity(&q).as_slice(),
            paper.gravity(&q).as_slice()
        ));
        // Written out, the scenario holds the file's text once and reads without its folder
        // into the very same models.
        let written = r.to_toml();
        assert_eq!(written.matches("<robot name=\"paper-two-link\"").count(), 1);
        let again = crate::scenario::load_str(&written, "run", None).expect("reads back");
        assert!(again.scenario.agents == r.scenario.agents, "other agents");
        assert!(again.scenario.urdf_files == r.scenario.urdf_files);
    }

    #[cfg(feature = "urdf")]
    #[test]
    fn a_trajectory_beyond_a_urdf_joint_s_limits_is_named_and_the_start_pose_brings_it_in() {
        use crate::model::Vector;
        let folder = repo().join("scenarios");
        let shipped = std::fs::read_to_string(folder.join("panda-team.toml")).expect("read");
        let load = |text: &str| crate::scenario::load_str(text, "panda-team.toml", Some(&folder));
        let r = load(&shipped).expect("the shipped Panda team");
        // The robot and its observer begin at the start pose, q_d too.
        let a = &r.scenario.agents[0];
        let ready = [0.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0].map(f64::to_radians);
        let plant = crate::plant::Plant::<7>::new(r.scenario.plant_params(a)).expect("plant");
        assert_eq!(plant.q, Vector::<7>::from_column_slice(&ready));
        let params = r.scenario.center_params(a);
        let model = params.model.build::<7>().expect("seven joints");
        let center = crate::control::paper::Paper::<7>::traditional(&params, model.as_ref())
            .expect("the traditional controller");
        assert_eq!(center.prediction().0, plant.q);
        assert_eq!(a.trajectory.reference::<7>(0.0).q, plant.q);

        let start = "start = [0.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0]";
        assert!(shipped.contains(start));
        let problems = |text: &str| load(text).expect_err("refused").problems;
        // Without its start, robot 1's fourth joint (limits [−3.0718, −0.0698]) and sixth
        // ([−0.0175, 3.7525]) would swing about 0.
        let p = problems(&shipped.replacen(start, "", 1));
        let named: Vec<_> = p.iter().map(|p| p.path.as_str()).collect();
        assert_eq!(
            named,
            [
                "agents[0].trajectory.links[3]",
                "agents[0].trajectory.links[5]"
            ],
            "{p:?}"
        );
        assert!(
            p[0].message.contains("`panda_joint4`") && p[0].message.contains("[-3.0718, -0.0698]"),
            "{p:?}"
        );
        // A start near a limit: joint 1 at 160 deg swings to 180 deg, beyond 2.8973 rad.
        let p = problems(&shipped.replacen(
            start,
            "start = [160.0, -45.0, 0.0, -135.0, 0.0, 90.0, 45.0]",
            1,
        ));
        assert_eq!(p.len(), 1, "{p:?}");
        assert_eq!(p[0].path, "agents[0].trajectory.links[0]");
        assert!(p[0].message.contains("`panda_joint1`"), "{p:?}");
        // A start of the wrong length, or not finite.
        let p = problems(&shipped.replacen(start, "start = [0.0, -45.0]", 1));
        assert_eq!(p.len(), 1, "{p:?}");
        assert_eq!(p[0].path, "agents[0].trajectory.start");
        assert!(p[0].message.contains("needs 7 entries"), "{p:?}");
        let p = problems(&shipped.replacen(
            start,
            "start = [0.0, -45.0, 0.0, -135.0, 0.0, nan, 45.0]",
            1,
        ));
        assert_eq!(p[0].path, "agents[0].trajectory.start[5]", "{p:?}");
    }

    #[cfg(feature = "urdf")]
    #[test]
    fn a_missing_urdf_an_arm_of_another_joint_count_and_a_broken_one_are_named_once() {
        let dir = tempfile::tempdir().expect("tempdir");
        let paper = crate::scenario::PAPER_SCENARIO;
        let load = |model: &str| {
            let text = paper.replacen(
                "model = { kind = \"two-link\" }",
                &format!("model = {{ kind = \"urdf\", {model} }}"),
                1,
            );
            crate::scenario::load_str(&text, "s.toml", Some(dir.path()))
                .expect_err("refused")
                .problems
        };
        let p = load("path = \"missing.urdf\"");
        assert_eq!(p.len(), 1, "{p:?}");
        assert_eq!(p[0].path, "agents[0].model.path");
        assert!(p[0].message.contains("missing.urdf"), "{p:?}");

        // Thirteen joints: one more than the largest joint count.
        let mut snake = String::from("<robot name=\"snake13\"><link name=\"l0\"/>");
        for i in 1..=13 {
            snake.push_str(&format!(
                "<link name=\"l{i}\"><inertial><mass value=\"1\"/><inertia ixx=\"1\" \
                 ixy=\"0\" ixz=\"0\" iyy=\"1\" iyz=\"0\" izz=\"1\"/></inertial></link>\
                 <joint name=\"j{i}\" type=\"continuous\"><parent link=\"l{}\"/><child \
                 link=\"l{i}\"/><axis xyz=\"0 0 1\"/></joint>",
                i - 1
            ));
        }
        snake.push_str("</robot>");
        std::fs::write(dir.path().join("snake13.urdf"), snake).expect("write");
        let p = load("path = \"snake13.urdf\"");
        assert_eq!(p[0].path, "agents[0].model", "{p:?}");
        assert!(
            p[0].message
                .contains("13 joints move, at most 12 may: lock the others"),
            "{p:?}"
        );
        // Every other agent has two links: the paper's.
        assert_eq!(p.len(), 1, "{p:?}");

        std::fs::write(
            dir.path().join("broken.urdf"),
            "<robot name=\"b\"><link name=\"a\"/><joint name=\"j\" type=\"revolute\">\
             <parent link=\"a\"/><child link=\"nowhere\"/></joint></robot>",
        )
        .expect("write");
        let p = load("path = \"broken.urdf\"");
        assert_eq!(p.len(), 1, "{p:?}");
        assert_eq!(p[0].path, "agents[0].model", "{p:?}");
        assert!(p[0].message.contains("broken.urdf"), "{p:?}");
    }
}
