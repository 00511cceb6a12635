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
    match declared {
        Some(n) => {
            let need = 84 + 50 * n;
            if need > b.len() as u64 {
                Err(Error::input(
                    path,
                    format!(
                        "truncated or not an STL: binary header declares {} ({need} bytes) but the file has {}",
                        count(n, "triangle", "triangles"),
                        count(b.len() as u64, "byte", "bytes")
                    ),
                ))
            } else {
                // Trailing bytes after the declared triangles: some exporters pad files.
                let extra = b.len() as u64 - need;
                if extra >= 50 {
                    Err(Error::input(
                        path,
                        format!(
                            "not a valid STL: binary header declares {} ({need} bytes) but the file has {} bytes",
                            count(n, "triangle", "triangles"),
                            b.len()
                        ),
                    ))
                } else {
                    Ok((parse_binary(b, n as usize), "stl-binary"))
                }
            }
        }
        None => Err(Error::input(
            path,
            format!(
                "not an STL file: {} is too short for binary STL and it is not ASCII STL",
                count(b.len() as u64, "byte", "bytes")
            ),
        )),
    }
}

/// Encodes `triangles` as a binary STL: an 80-byte header of zeros, the count, and per
/// triangle a zero normal (readers recompute it from the corners), the corners and a zero
/// attribute word. [`load`](super::load) reads it back corner for corner.
#[cfg(any(test, feature = "internals"))]
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

fn parse_ascii(path: &Path, b: &[u8]) -> Result<Soup> {
    let mut tk = Tokens {
        text: b,
        pos: 0,
        line: 1,
    };
    let mut soup = Vec::new();
    let err = |line: usize, msg: String| Error::input(path, format!("line {line}: {msg}"));
    let eof = |line: usize| {
        Error::input(
            path,
            format!("ASCII STL ends inside a facet or solid (last line {line})"),
        )
    };
    let expect = |tk: &mut Tokens, word: &str| -> Result<()> {
        match tk.next() {
            Some((t, _)) if t.eq_ignore_ascii_case(word.as_bytes()) => Ok(()),
            Some((t, l)) => Err(err(
                l,
                format!("expected '{word}', found '{}'", String::from_utf8_lossy(t)),
            )),
            None => Err(eof(tk.line)),
        }
    };
    let number = |tk: &mut Tokens| -> Result<f32> {
        match tk.next() {
            Some((t, l)) => std::str::from_utf8(t)
                .ok()
                .and_then(|s| s.parse::<f32>().ok())
                .ok_or_else(|| {
                    err(
                        l,
                        format!("expected a number, found '{}'", String::from_utf8_lossy(t)),
                    )
                }),
            None => Err(eof(tk.line)),
        }
    };
    let mut solids = 0;
    loop {
        match tk.next() {
            None => break,
            Some((t, _)) if t.eq_ignore_ascii_case(b"solid") => {
                solids += 1;
                tk.skip_line(); // solid name
                loop {
                    match tk.next() {
                        None => return Err(eof(tk.line)),
                        Some((t, _)) if t.eq_ignore_ascii_case(b"endsolid") => {
                            tk.skip_line();
                            break;
                        }
                        Some((t, _)) if t.eq_ignore_ascii_case(b"facet") => {
                            expect(&mut tk, "normal")?;
                            for _ in 0..3 {
                                number(&mut tk)?;
                            }
                            expect(&mut tk, "outer")?;
                            expect(&mut tk, "loop")?;
                            let mut tri = [[0f32; 3]; 3];
                            for v in &mut tri {
                                expect(&mut tk, "vertex")?;
                                for c in v.iter_mut() {
                                    *c = number(&mut tk)?;
                                }
                            }
                            expect(&mut tk, "endloop")?;
                            expect(&mut tk, "endfacet")?;
                            soup.push(tri);
                        }
                        Some((t, l)) => {
                            return Err(err(
                                l,
                                format!(
                                    "expected 'facet' or 'endsolid', found '{}'",
                                    String::from_utf8_lossy(t)
                                ),
                            ))
                        }
                    }
                }
            }
            Some((t, l)) => {
                return Err(err(
                    l,
                    format!(
                        "expected 'solid', found '{}'",
                        String::from_utf8_lossy(&t[..t.len().min(40)])
                    ),
                ))
            }
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
