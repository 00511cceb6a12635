//! `dmdsl profile show|list`: the built-in machine profiles.

use crate::profile::{self, Profile};
use clap::Subcommand;

#[derive(Subcommand)]
pub(crate) enum ProfileCmd {
    /// Print a profile as TOML (built-in: with its comments), ready to copy and edit.
    Show {
        /// Built-in name or TOML file.
        name: String,
    },
    /// List the built-in profiles.
    List,
}

/// Runs `dmdsl profile ...`.
pub(crate) fn profile(cmd: ProfileCmd) -> anyhow::Result<u8> {
    match cmd {
        ProfileCmd::List => {
            for (name, src) in profile::BUILTIN {
                let p = Profile::from_toml(src, name)?;
                println!("{name}\t{}", p.description);
            }
            Ok(0)
        }
        ProfileCmd::Show { name } => {
            match profile::builtin_source(&name) {
                Some(src) => print!("{src}"),
                None => print!("{}", Profile::resolve(&name)?.to_toml()),
            }
            Ok(0)
        }
    }
}
