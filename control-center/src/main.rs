//! `fdi-control-center`: started by `fdi-launch`.

fn main() -> std::process::ExitCode {
    fdi_runtime::role::main(
        "fdi-control-center",
        "fdi-mas control-center process (started by fdi-launch)",
        fdi_control_center::run_process,
    )
}
