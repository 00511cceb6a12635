//! The regions the supports do not hold: a job with supports is checked as `dmdsl run`
//! checks its masks before it is written, and the layers whose correction leaves a
//! region of the layer above on nothing are drawn again without it (docs/CURE.md, "Layers
//! drawn uncorrected").

use super::cure_records::CureJob;
use super::{JobInputs, Made};
use crate::error::{Error, Result};
use crate::text::{first_of, plural};
use crate::warning::Warning;
use std::path::Path;

/// Passes of the pipeline after the first, at most, that draw more layers plain before
/// a job whose corrected masks leave regions on nothing is refused ([`made_held`]).
const PLAIN_PASSES: usize = 4;

/// Makes the job with `cure`. A job with supports whose corrected masks leave regions
/// that `dmdsl run` finds on nothing ([`crate::exec::unheld_regions`]: the correction
/// moved in or broke up the first layers of a thin feature, and what cures of the layer
/// below misses what rests on it) is made again with the layer below each such layer
/// (with the Z correction also the layers it held back) drawn as without the correction
/// ([`CureJob::drawn_plain`]), and the layer itself once those are, up to [`PLAIN_PASSES`]
/// more times; a job that still has such regions, or any job with
/// supports and no correction that has some, is an error naming the first, so that no
/// job `slice` writes fails `run` that way.
pub(super) fn made_held(
    inputs: &JobInputs,
    mut cure: Option<CureJob>,
) -> Result<(Made, Option<CureJob>)> {
    let mut made = super::make_job(inputs, cure.as_ref())?;
    let mut pass = 0;
    loop {
        let unheld = crate::exec::unheld_regions(&made.writer, &made.manifest, &made.field_runs);
        let Some(first) = unheld.first() else {
            return Ok((made, cure));
        };
        let more = |c: &CureJob| {
            let mut plain = c.plain().to_vec();
            let k = plain.len();
            // The layer below, and with the Z correction the layers it held back; the layer
            // itself once those are plain.
            let span = 1 + c.held_back();
            for l in unheld.iter().filter_map(|v| v.layer) {
                match plain.contains(&l.saturating_sub(1)) {
                    true => plain.push(l),
                    false => plain.extend(l.saturating_sub(span)..l),
                }
            }
            plain.sort_unstable();
            plain.dedup();
            (plain.len() > k && pass < PLAIN_PASSES).then_some(plain)
        };
        let Some(plain) = cure.as_ref().filter(|c| c.corrects()).and_then(more) else {
            return Err(unheld_error(
                inputs.part.path,
                first,
                unheld.len(),
                cure.as_ref(),
            ));
        };
        let spent = made.passes;
        // The first pass's files go (a directory bundle's staging directory with them).
        drop(made);
        inputs.setup.reset_counts();
        cure = CureJob::new(inputs.profile, &inputs.opts.cure)?.map(|c| c.drawn_plain(plain));
        made = super::make_job(inputs, cure.as_ref())?;
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
            "; with {} drawn without the cure correction the job still fails `dmdsl run`: slice with --cure-correction off, or orient the part so that the region rests on the layer below",
            plural(c.plain().len() as u64, "one layer", &format!("{} layers", c.plain().len())),
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
    let (&first, n) = (plain.first()?, plain.len() as u64);
    // Consecutive layers as one range.
    let mut ranges: Vec<(usize, usize)> = Vec::new();
    for &l in plain {
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
    let w = Warning::new(
        "cure.layers-uncorrected",
        format!(
            "cure: {n} {} drawn without the cure correction ({} {}): corrected, {} left regions on nothing that the supports do not hold",
            plural(n, "layer", "layers"),
            plural(n, "layer", "layers"),
            shown.replace("; ", ", "),
            plural(n, "it", "they"),
        ),
    );
    Some(
        w.with("layers", n)
            .with("first_layer", first as u64)
            .with("uncorrected", plain.to_vec()),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::job::CureOptions;
    use crate::profile::Profile;

    #[test]
    fn layers_drawn_plain_are_named_and_a_job_they_do_not_hold_is_refused() {
        let profile = Profile::default_profile();
        let cure = CureJob::new(&profile, &CureOptions::default())
            .unwrap()
            .expect("the default machine has a PSF");
        assert!(plain_warning(&cure).is_none());
        let cure = cure.drawn_plain(vec![12, 8, 9, 12, 40]);
        assert_eq!(cure.plain(), [8, 9, 12, 40]);
        assert!(cure.corrects() && cure.corrects_at(7) && !cure.corrects_at(9));
        assert!(cure.active_at(10) && !cure.active_at(40));
        assert_eq!(cure.record().uncorrected_layers, [8, 9, 12, 40]);
        let w = plain_warning(&cure).unwrap();
        assert_eq!(w.code, "cure.layers-uncorrected");
        assert!(
            w.message.starts_with(
                "cure: 4 layers drawn without the cure correction (layers 8-9, 12, 40)"
            ),
            "{}",
            w.message
        );
        assert_eq!(w.fields["first_layer"], 8);
        assert_eq!(w.fields["uncorrected"], serde_json::json!([8, 9, 12, 40]));

        let first = crate::exec::Violation {
            layer: Some(41),
            time_s: None,
            kind: crate::exec::Kind::UnsupportedRegion,
            message: "p.dmdjob/masks/00041.png: layer 41: 1 region rests on nothing".into(),
            file: None,
        };
        let e = unheld_error(Path::new("part.stl"), &first, 3, Some(&cure)).to_string();
        assert!(
            e.starts_with("part.stl: the supports do not hold every region: layer 41: 1 region rests on nothing (and 2 more layers); with 4 layers drawn without the cure correction"),
            "{e}"
        );
        assert!(e.contains("--cure-correction off"), "{e}");
        let e = unheld_error(Path::new("part.stl"), &first, 1, None).to_string();
        assert!(e.ends_with("rests on nothing; `dmdsl run` would reject the job: orient the part so that the region rests on the layer below"), "{e}");
    }
}
