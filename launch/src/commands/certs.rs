//! `fdi-launch certs`: the lab's certificates for the hosts of a deployment file
//! (`fdi_split::certs`), and which files go to which host.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use clap::Args;

/// `certs`.
#[derive(Debug, Clone, Args)]
pub struct CertsArgs {
    /// The deployment file: a certificate for each of its hosts.
    #[arg(long)]
    pub hosts: PathBuf,
    /// Where to write them (default: the file's `certs` folder). A CA already there signs the
    /// new certificates; no file is ever overwritten.
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// How many days the new host certificates are valid (from an hour before now, for clocks
    /// a little behind). Renew one by removing its pair and running this again.
    #[arg(long, default_value_t = 365, value_parser = clap::value_parser!(u32).range(1..=3650))]
    pub days: u32,
}

/// `certs`.
pub fn certs(args: &CertsArgs) -> Result<ExitCode> {
    let (out, made) = fdi_split::certs::certs(&args.hosts, args.out.as_deref(), args.days)?;
    if made.is_empty() {
        println!("{}: every host has its certificate already", out.display());
    }
    for p in &made {
        println!("made {}", p.display());
    }
    println!(
        "Copy to each host `ca.pem` and its own `<host>.pem` and `<host>.key` (into the folder \
         its deployment file names); keep `ca.key` on this machine only."
    );
    Ok(ExitCode::SUCCESS)
}
