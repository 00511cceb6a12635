//! OBJ reader through tobj (faces triangulated, materials ignored).

use super::Soup;
use crate::error::{Error, Result};
use std::path::Path;

pub(super) fn parse(path: &Path, bytes: &[u8]) -> Result<Soup> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let mut reader = std::io::BufReader::new(bytes);
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
                            "object '{}' face {fi}: vertex index {} out of range ({nv} vertices)",
                            m.name,
                            i + 1
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
        assert!(e.contains("out of"), "{e}");
    }
}
