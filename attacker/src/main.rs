//! `fdi-attacker`: started by `fdi-launch`.

fn main() -> std::process::ExitCode {
    fdi_runtime::role::main(
        "fdi-attacker",
        "fdi-mas attacker process (started by fdi-launch)",
        fdi_attacker::run_process,
    )
}
