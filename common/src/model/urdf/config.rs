//! A URDF arm as a scenario's model, `model = { kind = "urdf", path = "robots/arm.urdf", … }`:
//! its [`UrdfSpec`] and the arm read from the file's text, made once when the scenario is read.

use std::sync::Arc;

use serde::{Deserialize, Serialize};

use super::chain::{Chain, UrdfSpec};
use super::dynamics::UrdfArm;

/// The numbers of moving joints a URDF arm of a run may have: the math is generic over the
/// number of joints, and each count is compiled into every role (docs/model.md, "Your own arm";
/// the counts are `crate::model::joint_count`'s).
pub const JOINT_COUNTS: [usize; 12] = [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12];

// The messages and records carry every joint of the largest arm.
const _: () = assert!(JOINT_COUNTS[JOINT_COUNTS.len() - 1] <= crate::limits::MAX_DOF);

crate::per_joint_count!(
    /// A URDF arm of one of the [`JOINT_COUNTS`], its number of joints in its type.
    #[derive(Debug, Clone, PartialEq)]
    pub enum AnyArm = UrdfArm
);

impl AnyArm {
    /// The arm of `chain`; an error naming the robot when no [`JOINT_COUNTS`] fits it.
    pub fn new(chain: Chain) -> Result<Self, String> {
        let (name, dof) = (chain.name.clone(), chain.dof());
        let arm = crate::with_joint_count!(dof, N => UrdfArm::<N>::new(chain).map(Self::from));
        arm.flatten().ok_or_else(|| {
            format!(
                "`{name}` moves {dof} joint{}; a run's arms move {} joints (lock the others \
                 with `lock = {{ JOINT = VALUE }}`)",
                if dof == 1 { "" } else { "s" },
                counts_text()
            )
        })
    }

    /// The arm's joints and links as the URDF gave them.
    pub fn chain(&self) -> &Chain {
        crate::on_joint_count!(AnyArm, self, a => a.chain())
    }
}

/// [`JOINT_COUNTS`] as text: `1, 2, … 11 or 12`.
fn counts_text() -> String {
    let all: Vec<String> = JOINT_COUNTS.iter().map(ToString::to_string).collect();
    match all.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{} or {last}", rest.join(", ")),
        _ => all.concat(),
    }
}

/// `model = { kind = "urdf", … }`: the spec as the scenario wrote it and the arm read from the
/// file's text. Deserialized only from a spec whose text the scenario's loader put in
/// ([`UrdfSpec::text`]); serialized as the spec, without the text.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "UrdfSpec", into = "UrdfSpec")]
pub struct UrdfModel {
    spec: UrdfSpec,
    arm: Arc<AnyArm>,
}

impl UrdfModel {
    /// The arm `spec` names in the URDF text `text`.
    pub fn new(spec: UrdfSpec, text: &str) -> Result<Self, String> {
        let chain = Chain::parse(text, &spec, &spec.path).map_err(|e| e.to_string())?;
        Ok(Self {
            spec: UrdfSpec { text: None, ..spec },
            arm: Arc::new(AnyArm::new(chain)?),
        })
    }

    pub fn arm(&self) -> &AnyArm {
        &self.arm
    }
}

impl TryFrom<UrdfSpec> for UrdfModel {
    type Error = String;

    fn try_from(mut spec: UrdfSpec) -> Result<Self, String> {
        match spec.text.take() {
            Some(text) => Self::new(spec, &text),
            None => Err(format!(
                "{}: the URDF file was not read (a model of kind \"urdf\" is read with its \
                 scenario, its `path` relative to the scenario file)",
                spec.path.display()
            )),
        }
    }
}

impl From<UrdfModel> for UrdfSpec {
    fn from(m: UrdfModel) -> Self {
        m.spec
    }
}

impl schemars::JsonSchema for UrdfModel {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        UrdfSpec::schema_name()
    }

    fn json_schema(generator: &mut schemars::SchemaGenerator) -> schemars::Schema {
        UrdfSpec::json_schema(generator)
    }
}
