use super::super::Waveform;
use super::CorruptValue;
use crate::attack::AttackProfile;

fn profile(value: &str) -> Result<AttackProfile, toml::de::Error> {
    toml::from_str(&format!(
        r#"
name = "t"
[[channels]]
agent = 1
signal = "position"
links = [1]
units = "rad"
segments = [{{ from_s = 0.0, waveform = {{ kind = "corrupt", value = {value} }} }}]
"#
    ))
}

fn injected(p: &AttackProfile) -> f64 {
    let w = p.channels[0].segments[0].waveform;
    let mut rng = crate::rng::stream(1, 1, crate::rng::Purpose::AttackNoise { channel: 0 });
    w.value(0.0, 0.0, &mut rng)
}

#[test]
fn every_form_parses_to_its_value_and_passes_validation() {
    let dofs = [(1, 2)].into_iter().collect();
    for (text, check) in [
        (r#""nan""#, (|v: f64| v.is_nan()) as fn(f64) -> bool),
        (r#""NaN""#, |v| v.is_nan()),
        ("nan", |v| v.is_nan()),
        (r#""inf""#, |v| v == f64::INFINITY),
        (r#""+inf""#, |v| v == f64::INFINITY),
        ("inf", |v| v == f64::INFINITY),
        (r#""-inf""#, |v| v == f64::NEG_INFINITY),
        ("-inf", |v| v == f64::NEG_INFINITY),
        ("1e300", |v| v == 1e300),
        ("-1e300", |v| v == -1e300),
        ("7", |v| v == 7.0),
        ("0.25", |v| v == 0.25),
    ] {
        let p = profile(text).unwrap_or_else(|e| panic!("{text}: {e}"));
        assert!(check(injected(&p)), "{text} gave {}", injected(&p));
        assert!(
            p.problems(&dofs).is_empty(),
            "{text}: {:?}",
            p.problems(&dofs)
        );
    }
}

#[test]
fn other_strings_are_refused_naming_the_accepted_forms() {
    for bad in [r#""banana""#, r#""""#, r#""1e300""#, "true", "[1.0]"] {
        let e = profile(bad).expect_err(bad).to_string();
        assert!(
            e.contains("corrupt") || e.contains(CorruptValue::FORMS) || e.contains("invalid"),
            "{bad}: {e}"
        );
    }
    let e = profile(r#""banana""#).expect_err("banana").to_string();
    assert!(e.contains(CorruptValue::FORMS), "{e}");
}

#[test]
fn the_profile_round_trips_through_toml_with_nan_and_infinities() {
    for text in [r#""nan""#, r#""inf""#, r#""-inf""#, "1e300", "-0.5"] {
        let p = profile(text).unwrap_or_else(|e| panic!("{text}: {e}"));
        let written = toml::to_string(&p).unwrap_or_else(|e| panic!("{text}: {e}"));
        let again: AttackProfile =
            toml::from_str(&written).unwrap_or_else(|e| panic!("{text}: {e}\n{written}"));
        assert_eq!(again, p, "{text} written as\n{written}");
    }
}

#[test]
fn corrupt_is_exempt_from_the_finiteness_check_but_other_waveforms_are_not() {
    for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e300, f64::MAX] {
        let w = Waveform::Corrupt {
            value: CorruptValue::new(v),
        };
        assert!(w.problems().is_empty(), "{v}");
        assert!(!w.is_none());
        if !v.is_finite() {
            assert!(
                !Waveform::Constant { value: v }.problems().is_empty(),
                "{v}"
            );
        }
    }
    assert!(!Waveform::Constant { value: f64::NAN }.problems().is_empty());
    // Every NaN is stored canonically, so equal profiles compare equal.
    assert_eq!(
        CorruptValue::new(-f64::NAN),
        CorruptValue::new(f64::NAN),
        "NaN sign and payload are canonicalised"
    );
    assert_ne!(CorruptValue::new(0.0), CorruptValue::new(-0.0));
}
