//! Attack profiles shipped with the tool, selectable by name (`--attack paper`). They are the
//! files in `scenarios/attacks/`, embedded at build time so the binary works from anywhere.

use super::profile::AttackProfile;

/// `(name, TOML text)` of every preset.
pub const PRESETS: &[(&str, &str)] = &[
    (
        "paper",
        include_str!("../../../scenarios/attacks/paper.toml"),
    ),
    (
        "paper-linkwise",
        include_str!("../../../scenarios/attacks/paper-linkwise.toml"),
    ),
    ("none", include_str!("../../../scenarios/attacks/none.toml")),
    (
        "scale",
        include_str!("../../../scenarios/attacks/scale.toml"),
    ),
    (
        "sign-flip",
        include_str!("../../../scenarios/attacks/sign-flip.toml"),
    ),
    (
        "freeze",
        include_str!("../../../scenarios/attacks/freeze.toml"),
    ),
    (
        "actuator-bias",
        include_str!("../../../scenarios/attacks/actuator-bias.toml"),
    ),
    (
        "torque-delay",
        include_str!("../../../scenarios/attacks/torque-delay.toml"),
    ),
    (
        "dos-drop",
        include_str!("../../../scenarios/attacks/dos-drop.toml"),
    ),
    (
        "dos-burst",
        include_str!("../../../scenarios/attacks/dos-burst.toml"),
    ),
    (
        "dos-window",
        include_str!("../../../scenarios/attacks/dos-window.toml"),
    ),
    (
        "measurement-delay",
        include_str!("../../../scenarios/attacks/measurement-delay.toml"),
    ),
    (
        "forge-stamp",
        include_str!("../../../scenarios/attacks/forge-stamp.toml"),
    ),
    (
        "replay-original",
        include_str!("../../../scenarios/attacks/replay-original.toml"),
    ),
    (
        "covert",
        include_str!("../../../scenarios/attacks/covert.toml"),
    ),
    (
        "stealthy-bias",
        include_str!("../../../scenarios/attacks/stealthy-bias.toml"),
    ),
];

/// Names of the presets, for error messages.
pub fn names() -> Vec<&'static str> {
    PRESETS.iter().map(|p| p.0).collect()
}

/// The preset called `name`, parsed. The shipped files are checked by tests, so a parse error
/// here can only come from a broken build.
pub fn preset(name: &str) -> Option<AttackProfile> {
    let text = PRESETS.iter().find(|p| p.0 == name)?.1;
    toml::from_str(text).ok()
}

#[cfg(test)]
mod tests;
