//! `shoal summarize`: summary.json and the plots from a recording alone.

use std::path::PathBuf;

use crate::pipeline;

/// Arguments of `shoal summarize`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
From the recording alone: safety, formation, perception, mission, the MPC, the
end-to-end latency, the events and the wall time of the run. The processes'
runtime figures come from their last recorded statistics (about once a
simulated second); CPU time and peak memory are not in a recording and are
left empty. A recording cut short (Ctrl-C, SIGKILL) is read up to its last
complete chunk; `shoal recover` writes a whole copy first if you want one.")]
pub struct SummarizeCmd {
    /// The recording (MCAP written by `shoal run`).
    pub recording: PathBuf,
    /// Where summary.json and plots/ go (default: beside the recording).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Replace the summary.json and plots/ already in DIR.
    #[arg(long)]
    pub force: bool,
    /// No closing table.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs `shoal summarize`.
pub fn run(cmd: SummarizeCmd) -> anyhow::Result<()> {
    let out = cmd.out.unwrap_or_else(|| {
        cmd.recording
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .map_or_else(|| PathBuf::from("."), PathBuf::from)
    });
    if let Some(there) = pipeline::SUMMARY_OUTPUTS
        .iter()
        .map(|n| out.join(n))
        .find(|p| p.exists())
    {
        if !cmd.force {
            anyhow::bail!(
                "{} exists: pass --force to replace summary.json, plots/ and report.html, or choose --out (nothing was written)",
                there.display()
            );
        }
        pipeline::remove_all(&out, &pipeline::SUMMARY_OUTPUTS)?;
    }
    let s = pipeline::summarize_into(&cmd.recording, &out)?;
    if !cmd.quiet {
        super::run::print_table(&s);
    }
    println!("{}", out.display());
    Ok(())
}
