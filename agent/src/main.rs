//! `fdi-agent`: one agent process, started by `fdi-launch`.

fn main() -> std::process::ExitCode {
    fdi_runtime::role::main(
        "fdi-agent",
        "fdi-mas agent process (started by fdi-launch)",
        fdi_agent::run_process,
    )
}
