//! Picture files: PNG or JPEG, chosen by the file's extension.

use image::RgbImage;
use std::path::Path;

/// The file format of a picture.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// PNG (lossless; the default).
    Png,
    /// JPEG at quality [`JPEG_QUALITY`].
    Jpeg,
}

/// JPEG quality of written pictures (0–100): high, so thin lines and text stay clean.
pub const JPEG_QUALITY: u8 = 92;

impl Format {
    /// The format a picture path asks for by its extension (any case): `.png`, or `.jpg` /
    /// `.jpeg`. Anything else is refused with a one-line message naming the path and the
    /// extension.
    pub fn from_path(path: &Path) -> Result<Format, String> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(Format::Png),
            Some("jpg" | "jpeg") => Ok(Format::Jpeg),
            Some(e) => Err(format!(
                "{}: cannot write pictures as .{e}; use .png, .jpg or .jpeg",
                path.display()
            )),
            None => Err(format!(
                "{}: no extension to tell the picture format; use .png, .jpg or .jpeg",
                path.display()
            )),
        }
    }

    /// `img` encoded in this format.
    pub fn encode(self, img: &RgbImage) -> Vec<u8> {
        use image::ImageEncoder;
        let mut out = Vec::new();
        let (w, h) = img.dimensions();
        let result = match self {
            Format::Png => {
                use image::codecs::png::{CompressionType, FilterType, PngEncoder};
                PngEncoder::new_with_quality(
                    &mut out,
                    CompressionType::Default,
                    FilterType::Adaptive,
                )
                .write_image(img.as_raw(), w, h, image::ExtendedColorType::Rgb8)
            }
            Format::Jpeg => {
                image::codecs::jpeg::JpegEncoder::new_with_quality(&mut out, JPEG_QUALITY)
                    .write_image(img.as_raw(), w, h, image::ExtendedColorType::Rgb8)
            }
        };
        result.expect("encoding an RGB image to memory cannot fail");
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn format_follows_the_extension() {
        assert_eq!(Format::from_path(Path::new("a.png")), Ok(Format::Png));
        assert_eq!(Format::from_path(Path::new("a.PNG")), Ok(Format::Png));
        assert_eq!(Format::from_path(Path::new("d/a.jpg")), Ok(Format::Jpeg));
        assert_eq!(Format::from_path(Path::new("a.JPEG")), Ok(Format::Jpeg));
        let e = Format::from_path(Path::new("a.gif")).unwrap_err();
        assert!(e.starts_with("a.gif: ") && e.contains(".gif"), "{e}");
        assert!(Format::from_path(Path::new("plot")).is_err());
    }

    #[test]
    fn both_formats_decode() {
        let img = RgbImage::from_fn(40, 30, |x, _| image::Rgb([x as u8 * 6, 100, 200]));
        for f in [Format::Png, Format::Jpeg] {
            let back = image::load_from_memory(&f.encode(&img)).unwrap().to_rgb8();
            assert_eq!(back.dimensions(), (40, 30));
            let p = back.get_pixel(20, 15);
            assert!((p[1] as i32 - 100).abs() < 8, "{f:?}: {p:?}");
        }
    }
}
