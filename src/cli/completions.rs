//! `mpc-rig completions SHELL`: the shell completion script, generated from the same
//! argument definitions as `--help`, so it never lags a new flag.

use std::process::ExitCode;

use clap::{Args, CommandFactory};
use clap_complete::Shell;

use super::Cli;

/// Arguments of `mpc-rig completions` (where each shell's script goes is in its help, on
/// the subcommand in `cli`).
#[derive(Debug, Args)]
pub struct CompletionsArgs {
    /// The shell.
    #[arg(value_enum)]
    pub shell: Shell,
}

/// Write the script for `args.shell` to standard output.
pub fn run(args: CompletionsArgs) -> anyhow::Result<ExitCode> {
    let mut out = std::io::stdout().lock();
    clap_complete::generate(args.shell, &mut Cli::command(), "mpc-rig", &mut out);
    Ok(ExitCode::SUCCESS)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn script(shell: Shell) -> String {
        let mut out = Vec::new();
        clap_complete::generate(shell, &mut Cli::command(), "mpc-rig", &mut out);
        String::from_utf8(out).unwrap()
    }

    /// Guards that the scripts come from the real command tree: every subcommand and a
    /// flag added this round (`measure --live`) appear in the bash, zsh and fish scripts.
    #[test]
    fn scripts_name_every_subcommand_and_recent_flags() {
        let names: Vec<String> = Cli::command()
            .get_subcommands()
            .map(|c| c.get_name().to_string())
            .collect();
        assert!(names.len() >= 11, "{names:?}");
        for shell in [Shell::Bash, Shell::Zsh, Shell::Fish] {
            let s = script(shell);
            for n in &names {
                assert!(s.contains(n.as_str()), "{shell}: no {n}");
            }
            assert!(s.contains("live"), "{shell}: no --live");
        }
        assert!(script(Shell::Bash).contains("complete -F _mpc__rig "));
    }

    /// Guards the help the README points to: `completions --help` says where each
    /// shell's script goes.
    #[test]
    fn the_help_says_where_each_script_goes() {
        let mut cli = Cli::command();
        let help = cli
            .find_subcommand_mut("completions")
            .unwrap()
            .render_long_help()
            .to_string();
        for place in [
            "~/.local/share/bash-completion/completions/mpc-rig",
            "~/.zfunc/_mpc-rig",
            "~/.config/fish/completions/mpc-rig.fish",
        ] {
            assert!(help.contains(place), "{help}");
        }
    }

    /// Guards the bash script in bash itself: sourced, it completes `mpc-rig meas` to
    /// `measure` (skipped, saying so, where bash is missing).
    #[test]
    fn bash_completes_a_subcommand() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("mpc-rig.bash");
        std::fs::write(&file, script(Shell::Bash)).unwrap();
        let run = std::process::Command::new("bash")
            .arg("-c")
            .arg(format!(
                "source '{}'; COMP_WORDS=(mpc-rig meas); COMP_CWORD=1; \
                 COMP_LINE='mpc-rig meas'; COMP_POINT=12; _mpc__rig mpc-rig meas mpc-rig; \
                 echo \"${{COMPREPLY[@]}}\"",
                file.display()
            ))
            .output();
        match run {
            Ok(out) => assert_eq!(String::from_utf8_lossy(&out.stdout), "measure\n"),
            Err(e) => eprintln!("skipped: bash cannot run here ({e})"),
        }
    }
}
