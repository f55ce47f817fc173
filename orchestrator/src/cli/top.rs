//! `shoal top`: a live table of a running run's processes.

use std::path::PathBuf;
use std::time::{Duration, Instant};

use anyhow::Context as _;
use ipc_types::{Event, ProcessStats, RunChannel};
use ratatui::crossterm::event::{self, Event as TermEvent, KeyCode, KeyModifiers};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Modifier, Style};
use ratatui::widgets::{Block, Paragraph, Row as TableRow, Table};
use shoal_runtime::ChannelLimits;

use crate::top::{cells, headline, scan_procs, Snapshot, Top, COLUMNS};

/// Arguments of `shoal top`.
#[derive(Debug, clap::Args)]
#[command(after_help = "\
Columns: steps/s and cpu % over the last refresh; p50/p99 µs: step time over the
process's last statistics period (about a second: simulated in lockstep, wall
clock in realtime); misses: realtime deadline misses; restarts: from the run's
events; lost: input samples lost or refused. Below: per input channel kind, the
publish -> take latency over every reader, and the latest events.
The statistics come from the run's `stats` channel on this machine: a run
spread over hosts shows the processes of the host `shoal top` runs on.
Keys: q, Esc or Ctrl-C quits.")]
pub struct TopCmd {
    /// The run: its output directory (with run.json) or its run id
    /// (default: the one run running on this machine).
    pub run: Option<PathBuf>,
    /// Print one snapshot and exit (after one refresh interval, so that the
    /// rates have two samples).
    #[arg(long)]
    pub once: bool,
    /// With --once: the snapshot as JSON.
    #[arg(long, requires = "once")]
    pub json: bool,
    /// Refresh interval, s.
    #[arg(long, default_value_t = 1.0)]
    pub interval: f64,
}

/// Reads a run's `stats` and `events` as an outside client.
struct Feed {
    _node: iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    stats: shoal_runtime::Subscriber<ProcessStats>,
    events: shoal_runtime::Subscriber<Event>,
    recording: Option<PathBuf>,
    start: Instant,
}

impl Feed {
    fn open(run_id: &str) -> anyhow::Result<Self> {
        let procs = scan_procs(run_id);
        let processes = procs.iter().find_map(|p| p.processes).with_context(|| {
            format!("run {run_id}: none of its processes is running on this machine")
        })?;
        let recording = procs
            .iter()
            .find(|p| p.process == "recorder")
            .and_then(|p| p.out.clone());
        let node = shoal_runtime::domain_node(run_id, "run/top")?;
        let stats = shoal_runtime::node_subscriber::<ProcessStats, _>(
            &node,
            &ipc_types::run_service_name(run_id, RunChannel::Stats),
            &shoal_runtime::stats::stats_limits(processes),
            4,
        )?;
        let events = shoal_runtime::node_subscriber::<Event, _>(
            &node,
            &ipc_types::run_service_name(run_id, RunChannel::Events),
            &ChannelLimits::events(),
            shoal_runtime::EVENTS_HISTORY,
        )?;
        Ok(Self {
            _node: node,
            stats,
            events,
            recording,
            start: Instant::now(),
        })
    }

    /// Drains what arrived and samples `/proc`: the snapshot now.
    fn snapshot(&mut self, top: &mut Top, run_id: &str) -> anyhow::Result<Snapshot> {
        self.stats.take_all(|s| top.stats(&s))?;
        self.events.take_all(|e| top.event(&e))?;
        let procs = scan_procs(run_id);
        let bytes = self
            .recording
            .as_ref()
            .and_then(|p| std::fs::metadata(p).ok())
            .map(|m| m.len());
        Ok(top.snapshot(self.start.elapsed().as_secs_f64(), &procs, bytes))
    }
}

/// Runs `shoal top`.
pub fn run(cmd: TopCmd) -> anyhow::Result<()> {
    anyhow::ensure!(
        cmd.interval.is_finite() && cmd.interval >= 0.05,
        "--interval {}: at least 0.05 s",
        cmd.interval
    );
    let run_id = crate::top::resolve_run(cmd.run.as_deref())?;
    let mut feed = Feed::open(&run_id)?;
    let mut top = Top::new(&run_id);
    let interval = Duration::from_secs_f64(cmd.interval);
    if cmd.once {
        feed.snapshot(&mut top, &run_id)?;
        std::thread::sleep(interval);
        let s = feed.snapshot(&mut top, &run_id)?;
        if cmd.json {
            println!("{}", serde_json::to_string_pretty(&s)?);
        } else {
            print!("{}", crate::top::text(&s));
        }
        return Ok(());
    }
    let mut terminal = ratatui::init();
    let result = watch(&mut terminal, &mut feed, &mut top, &run_id, interval);
    ratatui::restore();
    if let Ok(Some(last)) = &result {
        println!("{}\nrun {run_id} is over", headline(last));
    }
    result.map(|_| ())
}

/// Redraws every `interval` until a key says quit (`None`) or the run's
/// processes are all gone (the last snapshot).
fn watch(
    terminal: &mut ratatui::DefaultTerminal,
    feed: &mut Feed,
    top: &mut Top,
    run_id: &str,
    interval: Duration,
) -> anyhow::Result<Option<Snapshot>> {
    let mut next = Instant::now();
    loop {
        if Instant::now() >= next {
            let s = feed.snapshot(top, run_id)?;
            terminal.draw(|f| draw(f, &s))?;
            if s.processes_running == 0 {
                return Ok(Some(s));
            }
            next += interval;
        }
        // Waits on the terminal for a key or the next refresh, whichever
        // comes first.
        let wait = next.saturating_duration_since(Instant::now());
        if event::poll(wait)? {
            if let TermEvent::Key(k) = event::read()? {
                let ctrl_c =
                    k.code == KeyCode::Char('c') && k.modifiers.contains(KeyModifiers::CONTROL);
                if ctrl_c || matches!(k.code, KeyCode::Char('q') | KeyCode::Esc) {
                    return Ok(None);
                }
            }
        }
    }
}

fn draw(f: &mut ratatui::Frame, s: &Snapshot) {
    let hop_lines = s.hops.len() as u16 + 3;
    let event_lines = s.events.len().min(5) as u16 + 2;
    let [head, procs, hops, events] = Layout::vertical([
        Constraint::Length(1),
        Constraint::Min(4),
        Constraint::Length(hop_lines),
        Constraint::Length(event_lines),
    ])
    .areas(f.area());
    f.render_widget(Paragraph::new(format!("{}   (q quits)", headline(s))), head);
    let bold = Style::default().add_modifier(Modifier::BOLD);
    let widths = [
        Constraint::Length(8),
        Constraint::Length(12),
        Constraint::Length(8),
        Constraint::Length(8),
        Constraint::Length(8),
        Constraint::Length(8),
        Constraint::Length(8),
        Constraint::Length(7),
        Constraint::Length(7),
        Constraint::Length(8),
        Constraint::Length(9),
        Constraint::Length(6),
    ];
    let rows = s.processes.iter().map(|r| TableRow::new(cells(r)));
    f.render_widget(
        Table::new(rows, widths)
            .header(TableRow::new(COLUMNS).style(bold))
            .block(Block::bordered().title(" processes ")),
        procs,
    );
    let hop_rows = s.hops.iter().map(|h| {
        TableRow::new([
            h.channel.clone(),
            h.readers.to_string(),
            h.count.to_string(),
            format!("{:.1}", h.p50_us),
            format!("{:.1}", h.p99_us),
            format!("{:.1}", h.max_us),
        ])
    });
    f.render_widget(
        Table::new(
            hop_rows,
            [
                Constraint::Length(18),
                Constraint::Length(8),
                Constraint::Length(10),
                Constraint::Length(10),
                Constraint::Length(10),
                Constraint::Length(10),
            ],
        )
        .header(
            TableRow::new(["input", "readers", "samples", "p50 µs", "p99 µs", "max µs"])
                .style(bold),
        )
        .block(Block::bordered().title(" publish → take latency per input ")),
        hops,
    );
    let recent: Vec<String> = s.events.iter().rev().take(5).rev().cloned().collect();
    f.render_widget(
        Paragraph::new(recent.join("\n")).block(Block::bordered().title(" events ")),
        events,
    );
}
