//! The registered controllers (docs/model.md, "Controllers"): one line each,
//! `Variant = "name" => module::Type::constructor;` (the module a sibling of this one), the
//! constructor a `fn(&CenterParams, &dyn EulerLagrange<N>) -> Option<C>` of a type `C`
//! implementing [`super::controller::Controller`].
//! [`super::config::ControllerMode`] (the scenario's `mode`) and the pipeline's
//! `super::center::build` are both made of this list.

/// Expands `$then! { the list }`.
macro_rules! with_controllers {
    ($then:ident) => {
        $then! {
            /// The paper's: observer, and the NN attack estimate `Ŝ` in (12) and (23).
            Proposed = "proposed" => paper::Paper::proposed;
            /// The paper's baseline: its observer, `Ŝ ≡ 0`, the weights not updated.
            Traditional = "traditional" => paper::Paper::traditional;
            /// Computed torque on the measured state predicted over the delay; no attack
            /// estimate.
            ComputedTorque = "computed-torque" => computed_torque::ComputedTorque::new;
            /// The traditional controller whose measurement a residual detector gates: the
            /// observer's prediction stands in for it while the alarm is on.
            Gated = "gated" => gated::Gated::new;
            /// The traditional law without its delay compensation: PD on the measurement.
            Pd = "pd" => pd::Pd::new;
            /// A program outside the project decides the torques (`[roles.controller]`).
            External = "external" => external::External::new;
        }
    };
}
pub(crate) use with_controllers;
