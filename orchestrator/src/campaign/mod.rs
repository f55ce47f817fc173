//! `shoal campaign`: N generated courses × K seeds, in lockstep, as many
//! runs at once as the cores allow; a table, a plot and JSON of how the
//! method fared. The campaign, not one scenario, is how a change to the
//! method is judged.
//!
//! Course `i` is of family `families[i mod F]` with course seed `i div F`
//! (so every family gets its share and the first `F` courses cover them
//! all); each runs with noise seeds `0..K`. Every run is a child `shoal run`
//! (a crash or a hang stays in its run), its scenario in
//! `OUT/courses/NAME.toml`, its output in `OUT/runs/NAME/`. A run passes
//! when [`judge`] finds nothing: the summary's safety verdict, the slot
//! error settled after the course and the leader at its goal.
//!
//! With `--space` every course is [`Family::Composed`] and draws its own
//! formation too ([`draw_formation`]): a shape, 5 to 50 vehicles, points or
//! images; the report adds tables per kind of feature, per group size and per
//! camera. `--first-course-seed` starts the course seeds elsewhere, so that a
//! method tuned on one range is judged on another it has never run.
//!
//! Running the same command again resumes: a run whose directory holds a
//! `summary.json` is not run again. Ctrl-C stops the runs under way (their
//! rows say `interrupted`) and writes the report of those finished.

pub mod report;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::mpsc;

use anyhow::Context;
use serde::{Deserialize, Serialize};

use crate::analysis::summary::{Summary, FINAL_WINDOW_S};
use crate::gen::{self, Family, GenOptions, Shape};

pub use report::{write_report, Report};

/// Largest slot error RMS over the settled end of a run for a pass, m.
pub const FINAL_RMS_LIMIT_M: f64 = 0.5;
/// Farthest the leader may end from its goal for a pass, m.
pub const GOAL_LIMIT_M: f64 = 1.0;

/// What to run.
#[derive(Debug, Clone)]
pub struct CampaignOptions {
    /// Formation shape.
    pub shape: Shape,
    /// Vehicles.
    pub vehicles: usize,
    /// File spacing, m.
    pub spacing_m: f64,
    /// Families, in order.
    pub families: Vec<Family>,
    /// Courses.
    pub courses: usize,
    /// Noise seeds per course.
    pub seeds: u64,
    /// Runs at once.
    pub jobs: usize,
    /// Output directory.
    pub out: PathBuf,
    /// The `shoal` binary to run each scenario with.
    pub shoal: PathBuf,
    /// `--bin-dir` for the runs.
    pub bin_dir: Option<PathBuf>,
    /// Keep every recording (default: only the failing runs').
    pub keep_recordings: bool,
    /// No progress bar.
    pub quiet: bool,
    /// Run the paper's method as published (`[method] generalised = false`):
    /// the "before" of a change to the method.
    pub published: bool,
    /// Camera model of every course.
    pub camera: shoal_scenario::CameraModel,
    /// Sample the whole space: composed courses, each with a formation drawn
    /// from its course seed ([`draw_formation`]); `shape`, `vehicles`,
    /// `camera` and `families` are then not used.
    pub space: bool,
    /// The first course seed (course `i` has seed `first_course_seed + i div F`).
    pub first_course_seed: u64,
    /// `--replace` flags every run gets: the user's own method.
    pub replace: Vec<String>,
    /// Earlier campaigns shown beside this one (`--beside`).
    pub beside: Vec<report::Beside>,
}

/// One run of the campaign.
#[derive(Debug, Clone, PartialEq)]
pub struct Job {
    /// `<family><course seed>-<shape>-<N>[-img]-s<seed>`.
    pub name: String,
    /// Family.
    pub family: Family,
    /// Course seed.
    pub course_seed: u64,
    /// Noise seed.
    pub seed: u64,
    /// Formation shape.
    pub shape: Shape,
    /// Vehicles.
    pub vehicles: usize,
    /// Camera model.
    pub camera: shoal_scenario::CameraModel,
}

/// Share of `--space` courses run with rendered images (groups of 5-9).
pub const SPACE_IMAGE_SHARE: f64 = 0.2;
/// Share of `--space` courses with 15-50 vehicles (point cameras).
pub const SPACE_LARGE_SHARE: f64 = 0.35;

/// The formation of `--space` course `course_seed`: with images
/// ([`SPACE_IMAGE_SHARE`]) 5-9 vehicles (a renderer per follower at a
/// 0.01 s tick costs the most per vehicle); otherwise 15-50 vehicles
/// ([`SPACE_LARGE_SHARE`]) or 5-14; the paper's five on a fifth of the small
/// groups, else triangle, V, column or grid.
pub fn draw_formation(course_seed: u64) -> (Shape, usize, shoal_scenario::CameraModel) {
    let mut rng = gen::SplitMix(course_seed ^ 0x464F_524D_4154);
    let mut unit = || rng.unit();
    let images = unit() < SPACE_IMAGE_SHARE;
    let large = !images && unit() < SPACE_LARGE_SHARE / (1.0 - SPACE_IMAGE_SHARE);
    let camera = if images {
        shoal_scenario::CameraModel::Image
    } else {
        shoal_scenario::CameraModel::Point
    };
    let (lo, hi) = match (images, large) {
        (true, _) => (5, 9),
        (false, true) => (15, 50),
        (false, false) => (5, 14),
    };
    let n = lo + ((hi - lo + 1) as f64 * unit()) as usize;
    if !large && unit() < 0.2 {
        return (Shape::Paper, 5, camera);
    }
    let shapes = [Shape::Triangle, Shape::V, Shape::Column, Shape::Grid];
    let shape = shapes[((shapes.len() as f64) * unit()) as usize % shapes.len()];
    (shape, n.min(hi), camera)
}

/// A run's name.
fn job_name(
    family: Family,
    course_seed: u64,
    shape: Shape,
    n: usize,
    cam: shoal_scenario::CameraModel,
    seed: u64,
) -> String {
    let img = if cam == shoal_scenario::CameraModel::Image {
        "-img"
    } else {
        ""
    };
    format!("{family}{course_seed}-{}-{n}{img}-s{seed}", shape.name())
}

/// How a run ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    /// Every criterion met.
    Pass,
    /// A criterion failed.
    Fail,
    /// The run itself failed (no summary).
    Error,
    /// Stopped by Ctrl-C.
    Interrupted,
}

/// One row of the campaign: a run and its figures.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunRow {
    /// Run name.
    pub name: String,
    /// Family.
    pub family: String,
    /// Course seed.
    pub course_seed: u64,
    /// Noise seed.
    pub seed: u64,
    /// Where its output is.
    pub dir: String,
    /// How it ended.
    pub status: Status,
    /// What failed (empty for a pass).
    pub failed: Vec<String>,
    /// Closest pair of vehicles, m.
    pub min_pair_m: Option<f64>,
    /// Closest any vehicle's centre came to an obstacle, m.
    pub clearance_m: Option<f64>,
    /// Longest time any follower was without a fix of its parent, s.
    pub parent_gap_s: Option<f64>,
    /// Slot error RMS over the last 30 s, m.
    pub final_rms_m: Option<f64>,
    /// Leader's distance from its goal at the end, m.
    pub goal_error_m: Option<f64>,
    /// Wall-clock time of the run, s.
    pub wall_s: f64,
    /// Formation shape.
    #[serde(default)]
    pub shape: String,
    /// Vehicles.
    #[serde(default)]
    pub vehicles: usize,
    /// Camera model (`point` or `image`).
    #[serde(default)]
    pub camera: String,
    /// The kinds of feature on a composed course.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub features: Vec<gen::Feature>,
}

/// Why a campaign cannot start.
#[derive(Debug, thiserror::Error)]
pub enum CampaignError {
    /// No course.
    #[error("--courses 0: a campaign needs at least one course")]
    NoCourses,
    /// No seed.
    #[error("--seeds 0: a campaign needs at least one seed")]
    NoSeeds,
    /// No family.
    #[error("no family of courses given")]
    NoFamilies,
}

/// The runs of a campaign, in order.
pub fn jobs(o: &CampaignOptions) -> Result<Vec<Job>, CampaignError> {
    if o.courses == 0 {
        return Err(CampaignError::NoCourses);
    }
    if o.seeds == 0 {
        return Err(CampaignError::NoSeeds);
    }
    if o.families.is_empty() && !o.space {
        return Err(CampaignError::NoFamilies);
    }
    let f = o.families.len();
    let mut out = Vec::new();
    for i in 0..o.courses {
        let (family, course_seed, (shape, vehicles, camera)) = if o.space {
            let cs = o.first_course_seed + i as u64;
            (Family::Composed, cs, draw_formation(cs))
        } else {
            (
                o.families[i % f],
                o.first_course_seed + (i / f) as u64,
                (o.shape, o.vehicles, o.camera),
            )
        };
        for seed in 0..o.seeds {
            out.push(Job {
                name: job_name(family, course_seed, shape, vehicles, camera, seed),
                family,
                course_seed,
                seed,
                shape,
                vehicles,
                camera,
            });
        }
    }
    Ok(out)
}

/// What keeps a run from passing (empty: it passes): the safety verdict,
/// then the slot error over the last [`FINAL_WINDOW_S`] (at most
/// [`FINAL_RMS_LIMIT_M`]) and the leader within [`GOAL_LIMIT_M`] of its goal.
pub fn judge(s: &Summary) -> Vec<String> {
    let mut failed = s.verdict.failed.clone();
    match s.formation.slot_error_rms_final_m {
        Some(x) if x < FINAL_RMS_LIMIT_M => {}
        Some(x) => failed.push(format!(
            "slot error RMS {x:.2} m over the last {FINAL_WINDOW_S} s (limit {FINAL_RMS_LIMIT_M} m)"
        )),
        None => failed.push(format!("no slot error over the last {FINAL_WINDOW_S} s")),
    }
    match s.mission.leader_goal_error_m {
        Some(x) if x <= GOAL_LIMIT_M => {}
        Some(x) => failed.push(format!(
            "leader {x:.2} m from its goal (limit {GOAL_LIMIT_M} m)"
        )),
        None => failed.push("leader's distance from its goal unknown".into()),
    }
    failed
}

/// The row of a finished run from its summary.
pub fn row(job: &Job, dir: &Path, s: &Summary, features: &[gen::Feature]) -> RunRow {
    let failed = judge(s);
    let status = if failed.is_empty() {
        Status::Pass
    } else {
        Status::Fail
    };
    RunRow {
        min_pair_m: s.safety.min_pair_distance_m,
        clearance_m: s.safety.min_obstacle_clearance_m,
        parent_gap_s: s
            .perception
            .longest_parent_gap_s
            .values()
            .copied()
            .reduce(f64::max),
        final_rms_m: s.formation.slot_error_rms_final_m,
        goal_error_m: s.mission.leader_goal_error_m,
        wall_s: s.wall_time_s,
        features: features.to_vec(),
        ..unfinished(job, dir, status, failed)
    }
}

/// The row of a run without figures (interrupted, or failed to run).
fn unfinished(job: &Job, dir: &Path, status: Status, failed: Vec<String>) -> RunRow {
    RunRow {
        name: job.name.clone(),
        family: job.family.name().to_string(),
        course_seed: job.course_seed,
        seed: job.seed,
        dir: dir.display().to_string(),
        status,
        failed,
        min_pair_m: None,
        clearance_m: None,
        parent_gap_s: None,
        final_rms_m: None,
        goal_error_m: None,
        wall_s: 0.0,
        shape: job.shape.name().to_string(),
        vehicles: job.vehicles,
        camera: match job.camera {
            shoal_scenario::CameraModel::Image => "image",
            _ => "point",
        }
        .to_string(),
        features: Vec::new(),
    }
}

/// Writes the scenario of every job into `OUT/courses/` (each planned as
/// `shoal gen` would, so `shoal check` accepts it); returns each job's
/// kinds of feature.
fn write_courses(o: &CampaignOptions, jobs: &[Job]) -> anyhow::Result<Vec<Vec<gen::Feature>>> {
    let dir = o.out.join("courses");
    std::fs::create_dir_all(&dir).with_context(|| format!("cannot create {}", dir.display()))?;
    let mut features = Vec::with_capacity(jobs.len());
    for j in jobs {
        let plan = gen::plan(&GenOptions {
            vehicles: j.vehicles,
            shape: j.shape,
            spacing_m: o.spacing_m,
            seed: j.seed,
            course: Some(j.family),
            course_seed: Some(j.course_seed),
            name: Some(j.name.clone()),
            camera: j.camera,
            ..GenOptions::default()
        })
        .with_context(|| format!("generating {}", j.name))?;
        features.push(
            plan.course
                .as_ref()
                .map(|c| c.features.clone())
                .unwrap_or_default(),
        );
        let text = gen::text(&plan).with_context(|| format!("generating {}", j.name))?;
        let path = dir.join(format!("{}.toml", j.name));
        let text = if o.published {
            format!("{text}\n[method]\ngeneralised = false\n")
        } else {
            text
        };
        std::fs::write(&path, text).with_context(|| format!("cannot write {}", path.display()))?;
    }
    Ok(features)
}

/// Runs the campaign and writes its report into `o.out`.
pub fn run(o: &CampaignOptions) -> anyhow::Result<Report> {
    use iceoryx2_bb_posix::signal::SignalHandler;
    let jobs = jobs(o)?;
    let features = write_courses(o, &jobs)?;
    // installs the SIGINT/SIGTERM handler
    let _ = SignalHandler::termination_requested();
    let bar = if o.quiet {
        indicatif::ProgressBar::hidden()
    } else {
        indicatif::ProgressBar::new(jobs.len() as u64)
    };
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} runs ({eta} left) {msg}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    let mut rows: Vec<Option<RunRow>> = vec![None; jobs.len()];
    let mut todo = Vec::new();
    for (i, j) in jobs.iter().enumerate() {
        let dir = o.out.join("runs").join(&j.name);
        match Summary::read(&dir.join("summary.json")) {
            // A run stopped part-way is run again.
            Ok(s) if !s.partial => {
                rows[i] = Some(row(j, &dir, &s, &features[i]));
                bar.inc(1);
            }
            _ => todo.push(i),
        }
    }
    let (tx, rx) = mpsc::channel::<(usize, i32, std::io::Result<std::process::ExitStatus>)>();
    let mut running: Vec<(usize, i32)> = Vec::new();
    let mut next = 0;
    let mut stopping = false;
    let (mut passed, mut failed) = (0usize, 0usize);
    for r in rows.iter().flatten() {
        if r.status == Status::Pass {
            passed += 1;
        } else {
            failed += 1;
        }
    }
    loop {
        while !stopping && running.len() < o.jobs.max(1) && next < todo.len() {
            let i = todo[next];
            next += 1;
            let job = &jobs[i];
            let dir = o.out.join("runs").join(&job.name);
            if dir.exists() {
                std::fs::remove_dir_all(&dir)
                    .with_context(|| format!("cannot clear {}", dir.display()))?;
            }
            std::fs::create_dir_all(&dir)?;
            let log = std::fs::File::create(dir.join("run.log"))?;
            let mut cmd = Command::new(&o.shoal);
            cmd.arg("run")
                .arg(o.out.join("courses").join(format!("{}.toml", job.name)))
                .arg("--out")
                .arg(&dir)
                .arg("--quiet")
                .stdin(Stdio::null())
                .stdout(log.try_clone()?)
                .stderr(log);
            if let Some(b) = &o.bin_dir {
                cmd.arg("--bin-dir").arg(b);
            }
            for r in &o.replace {
                cmd.arg("--replace").arg(r);
            }
            crate::launch::os::die_with_parent(&mut cmd);
            let mut child = cmd
                .spawn()
                .with_context(|| format!("cannot start {}", o.shoal.display()))?;
            let pid = child.id() as i32;
            running.push((i, pid));
            let tx = tx.clone();
            std::thread::spawn(move || {
                let r = child.wait();
                let _ = tx.send((i, pid, r));
            });
        }
        if running.is_empty() {
            break;
        }
        let got = rx.recv_timeout(std::time::Duration::from_millis(500));
        if !stopping && SignalHandler::termination_requested() {
            stopping = true;
            bar.println("interrupted: stopping the runs under way");
            for &(_, pid) in &running {
                crate::launch::os::send_signal(pid, libc::SIGINT);
            }
        }
        let Ok((i, pid, status)) = got else { continue };
        running.retain(|&(_, p)| p != pid);
        let job = &jobs[i];
        let dir = o.out.join("runs").join(&job.name);
        let r = match Summary::read(&dir.join("summary.json")) {
            Ok(s) if !s.partial => row(job, &dir, &s, &features[i]),
            _ if stopping => unfinished(job, &dir, Status::Interrupted, vec!["interrupted".into()]),
            other => unfinished(
                job,
                &dir,
                Status::Error,
                vec![format!(
                    "the run failed ({}; see {}): {}",
                    match status {
                        Ok(s) => s.to_string(),
                        Err(e) => e.to_string(),
                    },
                    dir.join("run.log").display(),
                    match other {
                        Ok(_) => "it stopped part-way".to_string(),
                        Err(e) => e.to_string(),
                    }
                )],
            ),
        };
        if r.status == Status::Pass {
            passed += 1;
            if !o.keep_recordings {
                let _ = std::fs::remove_file(dir.join("recording.mcap"));
            }
        } else if r.status != Status::Interrupted {
            failed += 1;
            bar.println(format!("FAIL {}: {}", r.name, r.failed.join("; ")));
        }
        rows[i] = Some(r);
        bar.set_message(format!("{passed} pass, {failed} fail"));
        bar.inc(1);
    }
    bar.finish_and_clear();
    let rows: Vec<RunRow> = rows.into_iter().flatten().collect();
    let report = Report::new(o, rows);
    write_report(&report, &o.out)?;
    Ok(report)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;
    use crate::analysis::summary::Stretch;

    fn options(courses: usize, seeds: u64, families: Vec<Family>) -> CampaignOptions {
        CampaignOptions {
            shape: Shape::Paper,
            vehicles: 5,
            spacing_m: 4.0,
            families,
            courses,
            seeds,
            jobs: 1,
            out: PathBuf::from("unused"),
            shoal: PathBuf::from("shoal"),
            bin_dir: None,
            replace: Vec::new(),
            beside: Vec::new(),
            keep_recordings: false,
            quiet: true,
            published: false,
            camera: shoal_scenario::CameraModel::Point,
            space: false,
            first_course_seed: 0,
        }
    }

    /// A summary every criterion passes.
    fn good() -> Summary {
        let mut s = Summary::default();
        s.safety.safe_distance_m = 2.0;
        s.safety.min_pair_distance_m = Some(3.5);
        s.safety.min_obstacle_clearance_m = Some(1.9);
        s.formation.slot_error_rms_final_m = Some(0.2);
        s.mission.leader_goal_error_m = Some(0.1);
        s.perception.longest_parent_gap_s.insert("F1".into(), 0.1);
        s
    }

    #[test]
    fn courses_go_round_the_families_and_every_seed_runs_each() {
        let o = options(7, 2, vec![Family::Gate, Family::Turn, Family::Slalom]);
        let j = jobs(&o).unwrap();
        assert_eq!(j.len(), 14);
        let names: Vec<&str> = j.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(
            &names[..6],
            [
                "gate0-paper-5-s0",
                "gate0-paper-5-s1",
                "turn0-paper-5-s0",
                "turn0-paper-5-s1",
                "slalom0-paper-5-s0",
                "slalom0-paper-5-s1"
            ]
        );
        assert_eq!(j[6].name, "gate1-paper-5-s0");
        assert_eq!(j[12].name, "gate2-paper-5-s0");
        assert!(matches!(
            jobs(&options(0, 1, vec![Family::Gate])),
            Err(CampaignError::NoCourses)
        ));
        assert!(matches!(
            jobs(&options(1, 0, vec![Family::Gate])),
            Err(CampaignError::NoSeeds)
        ));
        assert!(matches!(
            jobs(&options(1, 1, vec![])),
            Err(CampaignError::NoFamilies)
        ));
    }

    #[test]
    fn a_run_passes_only_when_every_criterion_does() {
        assert!(judge(&good()).is_empty());
        let mut s = good();
        s.formation.slot_error_rms_final_m = Some(0.6);
        let f = judge(&s);
        assert_eq!(f.len(), 1);
        assert!(f[0].contains("0.60 m over the last 30 s"), "{f:?}");
        let mut s = good();
        s.mission.leader_goal_error_m = Some(1.5);
        assert!(judge(&s)[0].contains("1.50 m from its goal"));
        let mut s = good();
        s.mission.leader_goal_error_m = None;
        s.formation.slot_error_rms_final_m = None;
        assert_eq!(judge(&s).len(), 2, "a missing figure fails, never passes");
        let mut s = good();
        s.verdict.failed = vec!["F1 in contact with an obstacle".into()];
        assert_eq!(
            judge(&s),
            vec!["F1 in contact with an obstacle".to_string()]
        );
    }

    #[test]
    fn the_report_tallies_per_family_and_lists_the_failures_with_their_paths() {
        let o = options(2, 2, vec![Family::Gate, Family::Offset]);
        let j = jobs(&o).unwrap();
        let mut rows: Vec<RunRow> = j
            .iter()
            .map(|j| {
                row(
                    j,
                    &PathBuf::from(format!("/c/runs/{}", j.name)),
                    &good(),
                    &[],
                )
            })
            .collect();
        let mut bad = good();
        bad.safety.min_obstacle_clearance_m = Some(0.4);
        bad.verdict.failed = vec!["obstacle clearance 0.40 m below half the safe distance".into()];
        bad.perception.parent_lost = vec![Stretch::default()];
        rows[3] = row(
            &j[3],
            &PathBuf::from("/c/runs/offset0-paper-5-s1"),
            &bad,
            &[],
        );
        rows[1].status = Status::Interrupted;
        let r = Report::new(&o, rows);
        assert_eq!(r.overall.runs, 3);
        assert_eq!(r.overall.passed, 2);
        assert_eq!(r.interrupted, 1);
        let gate = &r.by_family[0];
        assert_eq!((gate.runs, gate.passed, gate.pass_rate), (1, 1, Some(1.0)));
        let offset = &r.by_family[1];
        assert_eq!((offset.runs, offset.passed), (2, 1));
        assert_eq!(offset.worst_clearance_m, Some(0.4));
        let md = r.markdown();
        assert!(md.contains("| offset | 2 | 1 | 50.0 % |"), "{md}");
        assert!(md.contains("| all | 3 | 2 | 66.7 % |"), "{md}");
        assert!(
            md.contains("- `/c/runs/offset0-paper-5-s1`: obstacle clearance 0.40 m"),
            "{md}"
        );
        assert!(md.contains("1 run(s) interrupted"));
        let back: Report = serde_json::from_str(&serde_json::to_string(&r).unwrap()).unwrap();
        assert_eq!(back, r);
    }
}
