//! The `mpc-rig` binary: parse the command line, run it, and turn errors into one clear
//! message with its cause chain and a non-zero exit code.

use std::process::ExitCode;

use clap::Parser;

fn main() -> ExitCode {
    let cli = mpc_rig::cli::Cli::parse();
    mpc_rig::cli::init_logging(cli.verbose, cli.quiet);
    match mpc_rig::cli::run(cli) {
        Ok(code) => code,
        Err(err) => {
            eprintln!("error: {err}");
            for cause in err.chain().skip(1) {
                eprintln!("  caused by: {cause}");
            }
            ExitCode::from(mpc_rig::cli::exit_code_for(&err))
        }
    }
}
