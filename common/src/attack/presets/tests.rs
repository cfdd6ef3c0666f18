#[test]
fn every_preset_parses() {
    for (name, text) in super::PRESETS {
        let parsed: Result<super::AttackProfile, _> = toml::from_str(text);
        assert!(parsed.is_ok(), "preset {name}: {parsed:?}");
    }
}
