//! `shoal export`: a recording for other viewers (Foxglove).

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::export::{export_to_file, ExportOptions, ExportReport};

/// Arguments of `shoal export`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Channels written (Foxglove's protobuf schemas, embedded; Foxglove and Rerun open the file):
  /tf                    foxglove.FrameTransforms  world (ENU) -> ned -> <V>/body, <V>/level
  /scene/obstacles       foxglove.SceneUpdate      scenario obstacles, in ned
  /scene/vehicles        foxglove.SceneUpdate      hull, heading arrow, name, beacons
  /scene/slots           foxglove.SceneUpdate      each follower's slot in its parent's level frame
  /scene/sonar           foxglove.SceneUpdate      sonar beams, red to the echo
  /scene/line_of_sight   foxglove.SceneUpdate      camera -> parent's beacons, green seen / red not
  /<V>/pose              foxglove.PoseInFrame      true pose, in ned
  /<F>/parent_estimate   foxglove.PoseInFrame      the parent as the camera estimated it
Times are the recording's simulation time, so the view starts at 1970-01-01 00:00:00;
--epoch adds the run's wall-clock start (kept in the recording) and viewers show the date.
A file shoal did not write is refused.")]
pub struct ExportCmd {
    /// The shoal recording (MCAP), e.g. runs/paper-<time>/recording.mcap.
    pub recording: PathBuf,
    /// Write a Foxglove-ready MCAP here: obstacles, vehicles, slots, sonar
    /// beams and the camera's line of sight as foxglove.SceneUpdate,
    /// frames as foxglove.FrameTransforms, poses as foxglove.PoseInFrame
    /// (protobuf). Open it in Foxglove and pick the `world` frame (ENU,
    /// z up), or in Rerun (`rerun FILE`).
    #[arg(long, value_name = "OUT")]
    pub foxglove: PathBuf,
    /// Replace OUT if it exists (it is refused otherwise).
    #[arg(long)]
    pub force: bool,
    /// Shift every time by the run's wall-clock start, so that viewers show
    /// the real date and time of day (default: simulated time from 0).
    #[arg(long)]
    pub epoch: bool,
    /// No progress bar and no closing table.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Runs `shoal export`.
pub fn run(cmd: ExportCmd) -> anyhow::Result<()> {
    let out = &cmd.foxglove;
    let opts = ExportOptions {
        force: cmd.force,
        progress: !cmd.quiet,
        epoch: cmd.epoch,
    };
    let report = export_to_file(&cmd.recording, out, opts)?;
    for n in &report.notes {
        tracing::warn!("{n}");
    }
    if !cmd.quiet {
        match print(&report, out, cmd.epoch) {
            // A closed pipe (`| head`) is the reader's choice, not an error.
            Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => return Err(e.into()),
            _ => {}
        }
    }
    Ok(())
}

/// Prints the closing table on stdout.
fn print(report: &ExportReport, out: &Path, epoch: bool) -> std::io::Result<()> {
    let mut o = std::io::stdout().lock();
    writeln!(
        o,
        "{}: {} messages on {} channels, {:.1} s .. {:.1} s (sim time{})",
        out.display(),
        report.messages(),
        report.channels.len(),
        report.span_ns.0 as f64 * 1e-9,
        report.span_ns.1 as f64 * 1e-9,
        if epoch {
            ", written from the run's wall-clock start"
        } else {
            ""
        }
    )?;
    writeln!(o, "{:<26} {:<26} {:>8}", "topic", "schema", "messages")?;
    for (topic, schema, n) in &report.channels {
        writeln!(o, "{topic:<26} {schema:<26} {n:>8}")?;
    }
    Ok(())
}
