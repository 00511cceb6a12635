//! STL reader (binary and ASCII, told apart by content and size) and binary writer.

use super::Soup;
use crate::error::{Error, Result};
use crate::text::count;
use std::path::Path;

/// Parses an STL file. Binary when the size matches the header's triangle count
/// (files whose 80-byte header starts with "solid" exist); ASCII when the text starts
/// with `solid` and parses as ASCII STL.
pub(super) fn parse(path: &Path, b: &[u8]) -> Result<(Soup, &'static str)> {
    let declared = (b.len() >= 84).then(|| u32::from_le_bytes([b[80], b[81], b[82], b[83]]) as u64);
    if let Some(n) = declared {
        if 84 + 50 * n == b.len() as u64 {
            return Ok((parse_binary(b, n as usize), "stl-binary"));
        }
    }
    let head = &b[..b.len().min(512)];
    let text_start = head
        .iter()
        .position(|c| !c.is_ascii_whitespace())
        .unwrap_or(head.len());
    let looks_ascii = head[text_start..].starts_with(b"solid") && !head.contains(&0);
    if looks_ascii {
        return Ok((parse_ascii(path, b)?, "stl-ascii"));
    }
    let Some(n) = declared else {
        return Err(Error::input(
            path,
            format!(
                "not an STL file: {} is too short for binary STL and it is not ASCII STL",
                count(b.len() as u64, "byte", "bytes")
            ),
        ));
    };
    // Up to 49 bytes after the declared triangles: some exporters pad files.
    let need = 84 + 50 * n;
    if need <= b.len() as u64 && b.len() as u64 - need < 50 {
        return Ok((parse_binary(b, n as usize), "stl-binary"));
    }
    let what = if need > b.len() as u64 {
        "truncated or not an STL"
    } else {
        "not a valid STL"
    };
    Err(Error::input(
        path,
        format!(
            "{what}: binary header declares {} ({need} bytes) but the file has {}",
            count(n, "triangle", "triangles"),
            count(b.len() as u64, "byte", "bytes")
        ),
    ))
}

/// Encodes `triangles` as a binary STL: an 80-byte header of zeros, the count, and per
/// triangle a zero normal (readers recompute it from the corners), the corners and a zero
/// attribute word. The loader reads it back corner for corner.
pub fn binary_stl(triangles: &[[[f32; 3]; 3]]) -> Vec<u8> {
    let mut b = Vec::with_capacity(84 + 50 * triangles.len());
    b.resize(80, 0u8);
    b.extend((triangles.len() as u32).to_le_bytes());
    for t in triangles {
        b.extend([0u8; 12]);
        for v in t {
            for c in v {
                b.extend(c.to_le_bytes());
            }
        }
        b.extend([0u8; 2]);
    }
    b
}

fn parse_binary(b: &[u8], n: usize) -> Soup {
    use rayon::prelude::*;
    b[84..84 + 50 * n]
        .par_chunks_exact(50)
        .with_min_len(4096)
        .map(|rec| {
            let f = |o: usize| f32::from_le_bytes([rec[o], rec[o + 1], rec[o + 2], rec[o + 3]]);
            let v = |k: usize| {
                let o = 12 + 12 * k;
                [f(o), f(o + 4), f(o + 8)]
            };
            [v(0), v(1), v(2)]
        })
        .collect()
}

struct Tokens<'a> {
    text: &'a [u8],
    pos: usize,
    line: usize,
}

impl<'a> Tokens<'a> {
    fn next(&mut self) -> Option<(&'a [u8], usize)> {
        let t = self.text;
        while self.pos < t.len() && t[self.pos].is_ascii_whitespace() {
            if t[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        if self.pos >= t.len() {
            return None;
        }
        let start = self.pos;
        while self.pos < t.len() && !t[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        Some((&t[start..self.pos], self.line))
    }

    fn skip_line(&mut self) {
        while self.pos < self.text.len() && self.text[self.pos] != b'\n' {
            self.pos += 1;
        }
    }
}

fn parse_ascii<'a>(path: &Path, b: &'a [u8]) -> Result<Soup> {
    let mut tk = Tokens {
        text: b,
        pos: 0,
        line: 1,
    };
    let expected = |(t, l): (&[u8], usize), what: &str| {
        let t = String::from_utf8_lossy(t);
        Error::input(path, format!("line {l}: expected {what}, found '{t}'"))
    };
    // The next token, which a solid or a facet that has begun must have.
    let next = |tk: &mut Tokens<'a>| {
        tk.next().ok_or_else(|| {
            let msg = format!(
                "ASCII STL ends inside a facet or solid (last line {})",
                tk.line
            );
            Error::input(path, msg)
        })
    };
    let word = |tk: &mut Tokens<'a>, w: &str| match next(tk)? {
        (t, _) if t.eq_ignore_ascii_case(w.as_bytes()) => Ok(()),
        tok => Err(expected(tok, &format!("'{w}'"))),
    };
    let number = |tk: &mut Tokens<'a>| {
        let tok = next(tk)?;
        let n = std::str::from_utf8(tok.0)
            .ok()
            .and_then(|s| s.parse::<f32>().ok());
        n.ok_or_else(|| expected(tok, "a number"))
    };
    let mut soup = Vec::new();
    let mut solids = 0;
    while let Some((t, l)) = tk.next() {
        if !t.eq_ignore_ascii_case(b"solid") {
            return Err(expected((&t[..t.len().min(40)], l), "'solid'"));
        }
        solids += 1;
        tk.skip_line(); // solid name
        loop {
            let tok = next(&mut tk)?;
            if tok.0.eq_ignore_ascii_case(b"endsolid") {
                tk.skip_line();
                break;
            }
            if !tok.0.eq_ignore_ascii_case(b"facet") {
                return Err(expected(tok, "'facet' or 'endsolid'"));
            }
            word(&mut tk, "normal")?;
            for _ in 0..3 {
                number(&mut tk)?;
            }
            word(&mut tk, "outer")?;
            word(&mut tk, "loop")?;
            let mut tri = [[0f32; 3]; 3];
            for v in &mut tri {
                word(&mut tk, "vertex")?;
                for c in v.iter_mut() {
                    *c = number(&mut tk)?;
                }
            }
            word(&mut tk, "endloop")?;
            word(&mut tk, "endfacet")?;
            soup.push(tri);
        }
    }
    if solids == 0 {
        return Err(Error::input(path, "ASCII STL has no 'solid'"));
    }
    Ok(soup)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ascii_tri() -> String {
        "solid t\n facet normal 0 0 1\n  outer loop\n   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n  endloop\n endfacet\nendsolid t\n".into()
    }

    fn binary(tris: &[[[f32; 3]; 3]], header: &[u8]) -> Vec<u8> {
        let mut b = binary_stl(tris);
        b[..header.len()].copy_from_slice(header);
        b
    }

    #[test]
    fn ascii_and_binary_agree() {
        let p = Path::new("t.stl");
        let (a, fa) = parse(p, ascii_tri().as_bytes()).unwrap();
        assert_eq!(fa, "stl-ascii");
        // A binary file whose header starts with "solid" is still binary.
        let (b, fb) = parse(p, &binary(&a, b"solid but binary")).unwrap();
        assert_eq!(fb, "stl-binary");
        assert_eq!(a, b);
        // Header, count, then 50 bytes a triangle.
        let bytes = binary_stl(&a);
        assert_eq!(bytes.len(), 84 + 50);
        assert_eq!(&bytes[80..84], &1u32.to_le_bytes());
        assert_eq!(&bytes[84 + 12 + 12..84 + 12 + 16], &1f32.to_le_bytes());
    }

    #[test]
    fn ascii_errors_name_line() {
        let p = Path::new("t.stl");
        let cut = &ascii_tri()[..60];
        let e = parse(p, cut.as_bytes()).unwrap_err().to_string();
        assert!(e.starts_with("t.stl: "), "{e}");
        assert!(e.contains("ends inside"), "{e}");
        let bad = ascii_tri().replace("vertex 1 0 0", "vertex 1 x 0");
        let e = parse(p, bad.as_bytes()).unwrap_err().to_string();
        assert!(e.contains("line 5: expected a number, found 'x'"), "{e}");
    }

    #[test]
    fn truncated_binary() {
        let p = Path::new("t.stl");
        let tri = [[[0f32, 0., 0.], [1., 0., 0.], [0., 1., 0.]]; 3];
        let b = binary(&tri, b"x");
        let e = parse(p, &b[..b.len() - 30]).unwrap_err().to_string();
        assert!(e.contains("declares 3 triangles"), "{e}");
        let mut big = b.clone();
        big[80..84].copy_from_slice(&1_000_000u32.to_le_bytes());
        assert!(parse(p, &big)
            .unwrap_err()
            .to_string()
            .contains("declares 1000000"));
    }
}
