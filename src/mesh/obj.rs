//! OBJ reader through tobj (faces triangulated, materials ignored).

use super::Soup;
use crate::error::{Error, Result};
use crate::text::count;
use std::path::Path;

pub(super) fn parse(path: &Path, bytes: &[u8]) -> Result<Soup> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let faces = positions_only(path, bytes)?;
    let mut reader = std::io::BufReader::new(&faces[..]);
    let (models, _materials) =
        tobj::load_obj_buf(&mut reader, &opts, |_| Err(tobj::LoadError::OpenFileFailed))
            .map_err(|e| Error::input(path, format!("invalid OBJ: {e}")))?;
    let mut soup = Vec::new();
    for m in &models {
        let pos = &m.mesh.positions;
        let nv = pos.len() / 3;
        for (fi, f) in m.mesh.indices.chunks_exact(3).enumerate() {
            let mut tri = [[0f32; 3]; 3];
            for (k, &i) in f.iter().enumerate() {
                let i = i as usize;
                if i >= nv {
                    return Err(Error::input(
                        path,
                        format!(
                            "object '{}' face {fi}: vertex index {} out of range ({})",
                            m.name,
                            i + 1,
                            count(nv as u64, "vertex", "vertices")
                        ),
                    ));
                }
                tri[k] = [pos[3 * i], pos[3 * i + 1], pos[3 * i + 2]];
            }
            soup.push(tri);
        }
    }
    Ok(soup)
}

/// The OBJ text with every face vertex reduced to its position index (texture and normal
/// indices dropped: a mesh needs neither), each index checked against the vertices defined
/// so far (1-based, or negative counting back from the last). tobj resolves indices with
/// unchecked arithmetic, so an index far out of range would overflow inside it.
fn positions_only(path: &Path, bytes: &[u8]) -> Result<Vec<u8>> {
    let mut out = Vec::with_capacity(bytes.len());
    let mut vertices: i64 = 0;
    for (n, line) in bytes.split_inclusive(|&b| b == b'\n').enumerate() {
        let trimmed = line.trim_ascii_start();
        let mut words = trimmed
            .split(|b| b.is_ascii_whitespace())
            .filter(|w| !w.is_empty());
        match words.next() {
            Some(b"v") => vertices += 1,
            Some(b"f") => {
                out.push(b'f');
                for w in words {
                    let pos = w.split(|&b| b == b'/').next().unwrap_or_default();
                    let i = std::str::from_utf8(pos)
                        .ok()
                        .and_then(|t| t.parse::<i64>().ok())
                        .filter(|&i| i != 0 && i.unsigned_abs() <= vertices as u64);
                    if i.is_none() {
                        return Err(Error::input(
                            path,
                            format!(
                                "line {}: face vertex {:?} is not an index of the {} defined before it",
                                n + 1,
                                String::from_utf8_lossy(w),
                                match vertices {
                                    0 => "no vertices".to_string(),
                                    1 => "one vertex".to_string(),
                                    v => format!("{v} vertices"),
                                }
                            ),
                        ));
                    }
                    out.push(b' ');
                    out.extend_from_slice(pos);
                }
                out.push(b'\n');
                continue;
            }
            _ => {}
        }
        out.extend_from_slice(line);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quad_is_triangulated_and_bad_index_is_error() {
        let p = Path::new("q.obj");
        let src = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";
        assert_eq!(parse(p, src).unwrap().len(), 2);
        let bad = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 9\n";
        let e = parse(p, bad).unwrap_err().to_string();
        assert!(e.starts_with("q.obj: "), "{e}");
        assert!(
            e.contains("line 4: face vertex \"9\" is not an index of the 3 vertices"),
            "{e}"
        );
    }

    #[test]
    fn texture_normal_and_relative_indices() {
        let p = Path::new("q.obj");
        let src = b"v 0 0 0\nv 1 0 0\nv 1 1 0\nvn 0 0 1\nvt 0 0\nf 1/1/1 2//1 -1/1\n";
        let s = parse(p, src).unwrap();
        assert_eq!(s, vec![[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]]]);
        for bad in [
            "f 1//-9223372036854775808 2 3",
            "f -4 1 2",
            "f 0 1 2",
            "f 1 2 x",
        ] {
            let src = format!("v 0 0 0\nv 1 0 0\nv 1 1 0\n{bad}\n");
            let e = parse(p, src.as_bytes());
            if bad.contains("9223") {
                // A normal index is dropped, never resolved.
                assert!(e.is_ok(), "{bad}");
            } else {
                assert!(
                    e.unwrap_err().to_string().contains("is not an index"),
                    "{bad}"
                );
            }
        }
    }
}
