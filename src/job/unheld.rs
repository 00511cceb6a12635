//! The regions the supports do not hold: a job with supports is checked as `dmdsl run`
//! checks its masks before it is written, and where the correction leaves a region of
//! the layer above on nothing the layers are drawn again without it, in windows around
//! the region or whole ([`super::uncorrected`]; docs/CURE.md, "Layers drawn uncorrected").

use super::cure_records::CureJob;
use super::uncorrected::window_around;
use super::{JobInputs, Made};
use crate::error::{Error, Result};
use crate::text::{first_of, plural};
use crate::warning::Warning;
use std::path::Path;

/// Passes of the pipeline after the first, at most, that draw more of the job plain
/// before a job whose corrected masks leave regions on nothing is refused
/// ([`made_held`]): enough for the four steps of
/// [`super::uncorrected::Uncorrected::hold`] and a region or two that a pass brings out.
const PLAIN_PASSES: usize = 6;

/// Makes the job with `cure`. A job with supports whose corrected masks leave regions
/// that `dmdsl run` finds on nothing ([`crate::exec::unheld_regions`]: the correction
/// moved in or broke up the first layers of a thin feature, and what cures of the layer
/// below misses what rests on it) is made again with more of it drawn as without the
/// correction ([`CureJob::drawn_plain`]): a window around each such region in the layer
/// below, then in the region's own layer, then those layers whole (with the Z correction
/// whole from the first step, the layers it held back with the layer below:
/// [`super::uncorrected::Uncorrected::hold`]), up to [`PLAIN_PASSES`] more times; a job
/// that still has such regions, or any job with supports and no correction that has
/// some, is an error naming the first, so that no job `slice` writes fails `run` that
/// way.
pub(super) fn made_held(
    inputs: &JobInputs,
    mut cure: Option<CureJob>,
) -> Result<(Made, Option<CureJob>)> {
    let mut made = super::make_job(inputs, cure.as_ref(), None)?;
    let mut pass = 0;
    loop {
        let unheld = crate::exec::unheld_regions(&made.writer, &made.manifest, &made.field_runs);
        let Some(first) = unheld.violations.first() else {
            return Ok((made, cure));
        };
        let f = made.manifest.machine.field();
        let field = [f.width_px as usize, f.height_px as usize];
        let more = |c: &CureJob| {
            let mut plain = c.plain().clone();
            for &(l, b) in &unheld.regions {
                plain.hold(c.plain(), l, window_around(b, field), c.held_back());
            }
            (plain != *c.plain() && pass < PLAIN_PASSES).then_some(plain)
        };
        let Some(plain) = cure.as_ref().filter(|c| c.corrects()).and_then(more) else {
            return Err(unheld_error(
                inputs.part.path,
                first,
                unheld.violations.len(),
                cure.as_ref(),
            ));
        };
        let spent = made.passes;
        // The next pass writes over this one's files, taking the blocks it draws alike.
        let tried = cure.as_ref().map(|c| c.plain().clone()).unwrap_or_default();
        let again = made.again(tried);
        inputs.setup.reset_counts();
        cure = CureJob::new(inputs.profile, &inputs.opts.cure)?.map(|c| c.drawn_plain(plain));
        made = super::make_job(inputs, cure.as_ref(), Some(again))?;
        made.passes.slice_s += spent.slice_s;
        made.passes.masks_s += spent.masks_s;
        made.passes.analysis_cpu_s += spent.analysis_cpu_s;
        pass += 1;
    }
}

/// The error of a job with supports whose masks still leave regions on nothing: the
/// first layer's violation `first` (of `layers` layers), and what the correction `cure`
/// drew plain.
fn unheld_error(
    path: &Path,
    first: &crate::exec::Violation,
    layers: usize,
    cure: Option<&CureJob>,
) -> Error {
    let more = match layers {
        1 => String::new(),
        k => format!(
            " (and {} more {})",
            k - 1,
            plural(k as u64 - 1, "layer", "layers")
        ),
    };
    let hint = match cure.filter(|c| c.corrects()) {
        Some(c) => format!(
            "; with {} drawn without the cure correction, in part or whole, the job still fails `dmdsl run`: slice with --cure-correction off, or orient the part so that the region rests on the layer below",
            plural(c.plain().layers().len() as u64, "one layer", &format!("{} layers", c.plain().layers().len())),
        ),
        None => "; `dmdsl run` would reject the job: orient the part so that the region rests on the layer below".into(),
    };
    // From "layer N:" on: the mask file it names was not written.
    let m = &first.message;
    let from = first.layer.and_then(|l| m.find(&format!("layer {l}: ")));
    let what = &m[from.unwrap_or(0)..];
    Error::Job {
        path: path.into(),
        msg: format!("the supports do not hold every region: {what}{more}{hint}"),
    }
}

/// The warning naming the layers `cure` draws as without the correction
/// ([`CureJob::drawn_plain`]), if any.
pub(super) fn plain_warning(cure: &CureJob) -> Option<Warning> {
    let plain = cure.plain();
    let layers = plain.layers();
    let (&first, n) = (layers.first()?, layers.len() as u64);
    let whole = plain.whole_layers();
    let windows = plain.all_windows().count() as u64;
    let scope = match (windows, whole.len()) {
        (0, _) => "whole without the cure correction".to_string(),
        (w, 0) => format!(
            "without the cure correction in {w} {}",
            plural(w, "window", "windows")
        ),
        (w, k) => format!(
            "without the cure correction in {w} {} and {k} whole ({})",
            plural(w, "window", "windows"),
            ranges(&whole)
        ),
    };
    let (it, layer) = (plural(n, "it", "they"), plural(n, "layer", "layers"));
    let w = Warning::new(
        "cure.layers-uncorrected",
        format!(
            "cure: {n} {layer} ({}) drawn {scope}: corrected, {it} left regions of the layer above on nothing that the supports do not hold",
            ranges(&layers),
        ),
    );
    Some(
        w.with("layers", n)
            .with("first_layer", first as u64)
            .with("uncorrected", layers)
            .with("windows", windows)
            .with("whole", whole),
    )
}

/// `layers` (sorted) as "layer 4" or "layers 4-6, 9", the first six ranges.
fn ranges(layers: &[usize]) -> String {
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    for &l in layers {
        match ranges.last_mut() {
            Some(s) if s.1 + 1 == l => s.1 = l,
            _ => ranges.push((l, l)),
        }
    }
    let shown = first_of(
        ranges.iter().map(|&(a, b)| match a == b {
            true => a.to_string(),
            false => format!("{a}-{b}"),
        }),
        (6, ranges.len()),
        ("range", "ranges"),
    );
    let n = layers.len() as u64;
    format!(
        "{} {}",
        plural(n, "layer", "layers"),
        shown.replace("; ", ", ")
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::job::uncorrected::Uncorrected;
    use crate::job::CureOptions;
    use crate::profile::Profile;

    #[test]
    fn layers_drawn_plain_are_named_and_a_job_they_do_not_hold_is_refused() {
        let profile = Profile::default_profile();
        let cure = CureJob::new(&profile, &CureOptions::default())
            .unwrap()
            .expect("the default machine has a PSF");
        assert!(plain_warning(&cure).is_none());
        let whole = Uncorrected::default().with_whole([12, 8, 9, 12, 40]);
        let cure = cure.drawn_plain(whole.clone());
        assert_eq!(cure.plain().layers(), [8, 9, 12, 40]);
        assert!(cure.corrects() && cure.corrects_at(7) && !cure.corrects_at(9));
        assert!(cure.active_at(10) && !cure.active_at(40));
        assert_eq!(cure.record().uncorrected_layers, [8, 9, 12, 40]);
        assert!(cure.record().uncorrected_windows.is_empty());
        let w = plain_warning(&cure).unwrap();
        assert_eq!(w.code, "cure.layers-uncorrected");
        assert!(
            w.message.starts_with(
                "cure: 4 layers (layers 8-9, 12, 40) drawn whole without the cure correction: corrected, they left regions of the layer above on nothing"
            ),
            "{}",
            w.message
        );
        assert_eq!(w.fields["first_layer"], 8);
        assert_eq!(w.fields["uncorrected"], serde_json::json!([8, 9, 12, 40]));
        // Windows: a layer drawn with them is corrected elsewhere.
        let at = window_around([100, 50, 110, 60], [1024, 768]);
        let mut once = whole.clone();
        once.hold(&whole, 31, at, 0);
        let mut windows = once.clone();
        windows.hold(&once, 31, at, 0);
        let cure = CureJob::new(&profile, &CureOptions::default())
            .unwrap()
            .unwrap()
            .drawn_plain(windows);
        assert!(cure.corrects_at(30) && cure.active_at(31) && !cure.corrects_at(12));
        // A layer drawn plain, in windows or whole, shares its masks with no other.
        assert!(cure.shares_masks_at(29) && cure.shares_masks_at(32));
        assert!(!cure.shares_masks_at(30) && !cure.shares_masks_at(31));
        assert!(!cure.shares_masks_at(12));
        let r = cure.record();
        assert_eq!(r.uncorrected_layers, [8, 9, 12, 40]);
        let boxes: Vec<_> = r
            .uncorrected_windows
            .iter()
            .map(|w| (w.layer, w.box_px))
            .collect();
        assert_eq!(boxes, [(30, [92, 42, 118, 68]), (31, [92, 42, 118, 68])]);
        let w = plain_warning(&cure).unwrap();
        assert!(
            w.message.starts_with(
                "cure: 6 layers (layers 8-9, 12, 30-31, 40) drawn without the cure correction in 2 windows and 4 whole (layers 8-9, 12, 40): "
            ),
            "{}",
            w.message
        );
        assert_eq!(
            (&w.fields["windows"], &w.fields["whole"]),
            (&serde_json::json!(2), &serde_json::json!([8, 9, 12, 40]))
        );
        let cure = CureJob::new(&profile, &CureOptions::default())
            .unwrap()
            .unwrap()
            .drawn_plain(Uncorrected::default().with_whole([]));
        assert!(plain_warning(&cure).is_none());
        let mut one = Uncorrected::default();
        one.hold(&Uncorrected::default(), 5, at, 0);
        let cure = cure.drawn_plain(one);
        let w = plain_warning(&cure).unwrap();
        assert!(
            w.message.starts_with("cure: 1 layer (layer 4) drawn without the cure correction in 1 window: corrected, it left"),
            "{}",
            w.message
        );

        let first = crate::exec::Violation {
            layer: Some(41),
            time_s: None,
            kind: crate::exec::Kind::UnsupportedRegion,
            message: "p.dmdjob/masks/00041.png: layer 41: 1 region rests on nothing".into(),
            file: None,
        };
        let e = unheld_error(Path::new("part.stl"), &first, 3, Some(&cure)).to_string();
        assert!(
            e.starts_with("part.stl: the supports do not hold every region: layer 41: 1 region rests on nothing (and 2 more layers); with one layer drawn without the cure correction, in part or whole,"),
            "{e}"
        );
        assert!(e.contains("--cure-correction off"), "{e}");
        let e = unheld_error(Path::new("part.stl"), &first, 1, None).to_string();
        assert!(e.ends_with("rests on nothing; `dmdsl run` would reject the job: orient the part so that the region rests on the layer below"), "{e}");
    }
}
