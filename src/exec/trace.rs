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
    path: PathBuf,
    tmp: PathBuf,
    w: Option<BufWriter<File>>,
    err: Option<std::io::Error>,
    layers: Option<RangeInclusive<usize>>,
    m: Machine,
    last: Option<Segment>,
    times: Vec<f64>,
    rows: u64,
}

impl TraceWriter {
    /// Starts a trace at `path` for the segments of `layers` (all if `None`).
    pub fn create(path: &Path, layers: Option<RangeInclusive<usize>>, m: Machine) -> Result<Self> {
        let name = path
            .file_name()
            .ok_or_else(|| Error::Usage(format!("--trace {}: not a file name", path.display())))?;
        let tmp = path.with_file_name(format!(
            ".{}.tmp-{}",
            name.to_string_lossy(),
            std::process::id()
        ));
        let f = File::create(&tmp).map_err(|e| Error::io(path, e))?;
        let mut w = BufWriter::with_capacity(1 << 16, f);
        let err = writeln!(w, "{HEADER}").err();
        Ok(TraceWriter {
            path: path.to_path_buf(),
            tmp,
            w: Some(w),
            err,
            layers,
            m,
            last: None,
            times: Vec::with_capacity(4),
            rows: 0,
        })
    }

    fn row(&mut self, seg: &Segment, t: f64, end: bool) {
        if self.err.is_some() {
            return;
        }
        let Some(w) = self.w.as_mut() else { return };
        let pos = self.m.quantize(seg.position_at(t));
        let (vel, shutter, light, event) = if end {
            (0.0, ShutterState::Closed, false, "end")
        } else {
            (
                seg.velocity_at(t),
                seg.shutter,
                seg.light,
                seg.kind.name(),
            )
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
        let mut w = self.w.take().expect("finish once");
        if self.err.is_none() {
            self.err = w.flush().err();
        }
        drop(w);
        if let Some(e) = self.err.take() {
            return Err(Error::io(&self.path, e));
        }
        std::fs::rename(&self.tmp, &self.path).map_err(|e| Error::io(&self.path, e))?;
        Ok(self.rows)
    }
}

impl Drop for TraceWriter {
    fn drop(&mut self) {
        if self.w.take().is_some() {
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
