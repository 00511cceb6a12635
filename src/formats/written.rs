//! The files of a job as every form writes them ([`Trimmed`]): each PNG up to the end of
//! its `IEND` chunk, so bytes a PNG reader ignores are not copied (as many times as layers
//! repeat an image); and, before anything is written, how many bytes the images add up to
//! and the manifest a native form writes ([`survey`]).

use crate::bundle::{sha256_hex, BundleSource, Manifest, MaskPixels};
use crate::error::Result;
use rayon::prelude::*;
use std::borrow::Cow;
use std::collections::HashMap;
use std::path::PathBuf;

/// The files of a job, each PNG through its `IEND` chunk ([`png_len`]).
pub(super) struct Trimmed<'a>(pub &'a dyn BundleSource);

impl BundleSource for Trimmed<'_> {
    fn read(&self, rel: &str) -> std::io::Result<Cow<'_, [u8]>> {
        Ok(match self.0.read(rel)? {
            Cow::Borrowed(b) => Cow::Borrowed(&b[..png_len(b)]),
            Cow::Owned(mut b) => {
                b.truncate(png_len(&b));
                Cow::Owned(b)
            }
        })
    }

    fn shown(&self, rel: &str) -> PathBuf {
        self.0.shown(rel)
    }
}

/// How many of `bytes` a PNG reader reads: through the CRC of the `IEND` chunk; all of
/// them when they are not a PNG whose chunks lead to one.
pub(super) fn png_len(bytes: &[u8]) -> usize {
    const SIGNATURE: &[u8] = b"\x89PNG\r\n\x1a\n";
    if !bytes.starts_with(SIGNATURE) {
        return bytes.len();
    }
    let mut at = SIGNATURE.len();
    while let Some(head) = bytes.get(at..at + 8) {
        let len = u32::from_be_bytes([head[0], head[1], head[2], head[3]]) as usize;
        let end = at.saturating_add(12).saturating_add(len);
        if end > bytes.len() {
            break;
        }
        if &head[4..] == b"IEND" {
            return end;
        }
        at = end;
    }
    bytes.len()
}

/// One file as written: its bytes, the SHA-256 of the bytes when they are not the whole
/// file, and its pixels (in its own pixel grid) when asked for.
type Written = (u64, Option<String>, Option<MaskPixels>);

/// What writing `m` with `files` (trimmed) takes: the bytes its images add up to, each as
/// often as layers name it (a form that writes a repeated image once writes less), the
/// gray maps once for a `native` form; and the manifest a `native` form writes, recording
/// the hashes of the bytes written and every mask's pixels (counted from the decoded file
/// where the manifest has none). Errors name a file that cannot be read, or decoded for
/// its pixels.
pub(super) fn survey<'m>(
    m: &'m Manifest,
    files: &Trimmed,
    native: bool,
) -> Result<(u64, Cow<'m, Manifest>)> {
    let mut uses: HashMap<&str, (u64, bool)> = HashMap::new();
    for k in m.layers.iter().flat_map(|l| &l.masks) {
        let u = uses.entry(k.file.as_str()).or_default();
        u.0 += 1;
        u.1 |= native && k.pixels.is_none();
    }
    let maps = m.optics.iter().chain(&m.projector_optics);
    for o in maps.filter(|_| native) {
        uses.entry(o.gray_map.as_str()).or_insert((1, false));
    }
    let names: Vec<(&str, bool)> = uses.iter().map(|(f, u)| (*f, u.1)).collect();
    let seen: Vec<Written> = crate::error::in_order(names.par_iter().map(|&(rel, pixels)| {
        let whole = files.0.file(rel)?;
        let n = png_len(&whole);
        let sha = (n < whole.len()).then(|| sha256_hex(&whole[..n]));
        let px = pixels
            .then(|| crate::picture::read_mask(files, rel))
            .transpose()?
            .map(|g| MaskPixels::of_gray8(g.width(), g.as_raw()));
        Ok((n as u64, sha, px))
    }))?;
    let seen: HashMap<&str, Written> = names.iter().map(|n| n.0).zip(seen).collect();
    let bytes = uses.iter().map(|(f, u)| u.0 * seen[f].0).sum();
    let changed = seen.values().any(|w| w.1.is_some() || w.2.is_some());
    if !native || !changed {
        return Ok((bytes, Cow::Borrowed(m)));
    }
    let mut m = m.clone();
    let projectors = m.machine.projector.clone();
    for k in m.layers.iter_mut().flat_map(|l| &mut l.masks) {
        let (_, sha, px) = &seen[k.file.as_str()];
        k.sha256 = sha.clone().unwrap_or(std::mem::take(&mut k.sha256));
        let p = projectors.get(k.projector as usize);
        if let (None, Some(px), Some(p)) = (k.pixels, px, p) {
            let place = (
                [p.width_px, p.height_px],
                p.offset_px,
                [p.mirror_x, p.mirror_y],
            );
            k.pixels = Some(px.placed(place.0, place.1, place.2));
        }
    }
    for o in m.optics.iter_mut().chain(&mut m.projector_optics) {
        if let Some(sha) = &seen[o.gray_map.as_str()].1 {
            o.gray_map_sha256 = sha.clone();
        }
    }
    Ok((bytes, Cow::Owned(m)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_png_ends_with_its_iend_chunk() {
        let png = crate::png::encode_gray8(4, 3, &[0, 9, 0, 0, 0, 255, 255, 0, 0, 0, 0, 7]);
        assert_eq!(png_len(&png), png.len());
        let mut junk = png.clone();
        junk.extend_from_slice(&[0; 100]);
        assert_eq!(png_len(&junk), png.len());
        // Not a PNG, or chunks that run past the end: kept whole.
        assert_eq!(png_len(b"GIF89a and more"), 15);
        assert_eq!(png_len(&png[..png.len() - 1]), png.len() - 1);
        let files = crate::bundle::MemSource::new(
            std::path::Path::new("x.zip"),
            HashMap::from([("a.png".to_string(), junk)]),
        );
        assert_eq!(&*Trimmed(&files).read("a.png").unwrap(), &png[..]);
    }
}
