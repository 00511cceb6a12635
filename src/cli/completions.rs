//! `dmdsl completions SHELL`: the shell's completion script, on stdout.

use clap::{Args, CommandFactory};

#[derive(Args)]
pub(crate) struct CompletionsArgs {
    /// The shell to complete in.
    shell: clap_complete::Shell,
}

/// Runs `dmdsl completions`.
pub(crate) fn completions(a: CompletionsArgs) -> anyhow::Result<u8> {
    let mut cmd = super::Cli::command();
    clap_complete::generate(a.shell, &mut cmd, "dmdsl", &mut std::io::stdout());
    Ok(0)
}
