//! `--trace FILE.csv`: the simulated timeline as CSV, streamed while simulating.
//!
//! One row per change: each segment's start, the phase changes of a trapezoidal move
//! (end of acceleration, start of deceleration), the moment the layer's mask is on the
//! DMD, and a last row at the end of the job. A row gives the state from its time on;
//! the stage position is exact at the row's time (quantized to the stage's steps), so a
//! reader interpolating between rows sees the accelerating phases as straight lines.
//!
//! Columns: `time_s, stage_mm, velocity_mm_s, shutter` (closed/opening/open/closing),
//! `light` (1 while light reaches the resin), `mask` (layer whose mask is on the DMD, −1
//! while loading), `layer`, `event` (what the machine does: move, wait, load-wait,
//! shutter-open, expose, sweep, shutter-close, shutter-stuck, home, end).
//!
//! The file is written to a hidden temporary sibling and renamed into place when the
//! run is over, so a failed run leaves no half-written trace.

use super::sim::{Machine, Segment, ShutterState, Sink};
use crate::error::{Error, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::ops::RangeInclusive;
use std::path::{Path, PathBuf};

/// CSV header line.
pub const HEADER: &str = "time_s,stage_mm,velocity_mm_s,shutter,light,mask,layer,event";

/// Streams the timeline to a CSV file.
#[derive(Debug)]
pub struct TraceWriter {
    /// Where the trace goes.
    path: PathBuf,
    /// The temporary sibling written first, renamed to `path` at the end.
    tmp: PathBuf,
    /// The open temporary file (`None` once finished).
    writer: Option<BufWriter<File>>,
    /// The first write error; later rows are skipped.
    err: Option<std::io::Error>,
    /// The layers traced (all if `None`).
    layers: Option<RangeInclusive<usize>>,
    /// The machine (positions are written quantized to its steps).
    machine: Machine,
    /// The last segment traced (its end is the closing row).
    last: Option<Segment>,
    /// Reused buffer of a segment's row times.
    times: Vec<f64>,
    /// Rows written.
    rows: u64,
}

impl TraceWriter {
    /// Starts a trace at `path` for the segments of `layers` (all if `None`).
    pub fn create(
        path: &Path,
        layers: Option<RangeInclusive<usize>>,
        machine: Machine,
    ) -> Result<Self> {
        let tmp = crate::output::temp_sibling(path)
            .ok_or_else(|| Error::Usage(format!("--trace {}: not a file name", path.display())))?;
        crate::output::refuse_special(path)?;
        let f = File::create(&tmp).map_err(|e| crate::output::write_error(path, e))?;
        let mut w = BufWriter::with_capacity(1 << 16, f);
        let err = writeln!(w, "{HEADER}").err();
        Ok(TraceWriter {
            path: path.to_path_buf(),
            tmp,
            writer: Some(w),
            err,
            layers,
            machine,
            last: None,
            times: Vec::with_capacity(4),
            rows: 0,
        })
    }

    fn row(&mut self, seg: &Segment, t: f64, end: bool) {
        if self.err.is_some() {
            return;
        }
        let Some(w) = self.writer.as_mut() else {
            return;
        };
        let pos = self.machine.quantize(seg.position_at(t));
        let (vel, shutter, light, event) = if end {
            (0.0, ShutterState::Closed, false, "end")
        } else {
            (seg.velocity_at(t), seg.shutter, seg.light, seg.kind.name())
        };
        let mask: i64 = if t >= seg.mask_ready_s {
            seg.layer as i64
        } else {
            -1
        };
        let r = writeln!(
            w,
            "{t:.6},{pos:.6},{vel:.6},{},{},{mask},{},{event}",
            shutter.name(),
            light as u8,
            seg.layer
        );
        self.rows += 1;
        if let Err(e) = r {
            self.err = Some(e);
        }
    }

    /// Writes the closing row, flushes and moves the file into place; returns the rows
    /// written.
    pub fn finish(mut self) -> Result<u64> {
        if let Some(last) = self.last {
            self.row(&last, last.t1, true);
        }
        let mut w = self.writer.take().expect("finish once");
        if self.err.is_none() {
            self.err = w.flush().err();
        }
        drop(w);
        let done = match self.err.take() {
            Some(e) => Err(e),
            None => std::fs::rename(&self.tmp, &self.path),
        };
        done.map_err(|e| {
            // A full disk, or the path taken: the temporary file goes.
            let _ = std::fs::remove_file(&self.tmp);
            Error::io(&self.path, e)
        })?;
        Ok(self.rows)
    }
}

impl Drop for TraceWriter {
    fn drop(&mut self) {
        if self.writer.take().is_some() {
            let _ = std::fs::remove_file(&self.tmp);
        }
    }
}

impl Sink for TraceWriter {
    fn segment(&mut self, seg: &Segment) {
        if let Some(r) = &self.layers {
            if !r.contains(&seg.layer) {
                return;
            }
        }
        let mut times = std::mem::take(&mut self.times);
        times.clear();
        seg.phase_times(&mut times);
        if seg.mask_ready_s > seg.t0 && seg.mask_ready_s < seg.t1 {
            let i = times.partition_point(|&t| t < seg.mask_ready_s);
            if times.get(i) != Some(&seg.mask_ready_s) {
                times.insert(i, seg.mask_ready_s);
            }
        }
        for &t in &times {
            self.row(seg, t, false);
        }
        self.times = times;
        self.last = Some(*seg);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::exec::sim::simulate;
    use crate::exec::testutil::*;

    #[test]
    fn trace_rows_follow_the_timeline() {
        let m = two_layer_topdown();
        let dir = crate::test_support::scratch("trace", "rows");
        let path = dir.join("t.csv");
        let mach = Machine::of(&m.machine);
        let mut all = TraceWriter::create(&path, None, mach).unwrap();
        let part_path = dir.join("l1.csv");
        let mut part = TraceWriter::create(&part_path, Some(1..=1), mach).unwrap();
        simulate(&m, &[], &mut [&mut all, &mut part]);
        assert!(
            !path.exists(),
            "written in place of a temporary only at the end"
        );
        let rows = all.finish().unwrap();
        part.finish().unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], HEADER);
        assert_eq!(lines.len() as u64, rows + 1);
        let rows: Vec<Vec<&str>> = lines[1..].iter().map(|l| l.split(',').collect()).collect();
        let t: Vec<f64> = rows.iter().map(|r| r[0].parse().unwrap()).collect();
        assert!(t.windows(2).all(|w| w[0] <= w[1]));
        // Home, 2 layers × (2 moves × 3 phases + mask ready + wait + open + expose + close), end.
        assert_eq!(rows.len(), 1 + 2 * 11 + 1);
        assert_eq!(rows[0][7], "home");
        // The mask appears 0.02 s into the first move.
        assert_eq!(
            rows[2][..7],
            ["0.020000", "0.010000", "1.000000", "closed", "0", "0", "0"]
        );
        let expose = rows.iter().find(|r| r[7] == "expose").unwrap();
        assert_eq!(
            expose[..6],
            ["17.860000", "0.500000", "0.000000", "open", "1", "0"]
        );
        assert_eq!(rows.last().unwrap()[..1], ["59.820000"]);
        assert_eq!(rows.last().unwrap()[7], "end");
        // Light only when the shutter is open.
        assert!(rows.iter().all(|r| (r[4] == "1") == (r[3] == "open")));
        let part = std::fs::read_to_string(&part_path).unwrap();
        assert!(part
            .lines()
            .skip(1)
            .all(|l| l.split(',').nth(6) == Some("1")));
        let names = crate::test_support::names(&dir);
        assert_eq!(names, ["l1.csv", "t.csv"], "no temporaries left");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn an_unfinished_trace_leaves_nothing() {
        let dir = crate::test_support::scratch("trace", "unfinished");
        let w = TraceWriter::create(
            &dir.join("t.csv"),
            None,
            Machine::of(&crate::bundle::Machine::of(&profile())),
        )
        .unwrap();
        drop(w);
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0);
        let _ = std::fs::remove_dir_all(&dir);
    }
}
