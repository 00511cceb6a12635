//! Pictures for people: charts (stage position over time, S(g) curves, per-layer figures in
//! stacked panels) and heatmaps over the build plane, drawn with tiny-skia and written as
//! PNG or JPEG.
//!
//! - [`canvas`]: the RGB canvas every picture is drawn on (rectangles, lines, dots, text,
//!   pasted images) and its encoding.
//! - [`text`]: the compiled-in font (DejaVu Sans, `fixtures/fonts/`), real glyphs in mixed
//!   case (`mW/cm²`, `µm`, `×`, `°`).
//! - [`axes`]: scales, "nice" ticks and number labels, axis drawing.
//! - [`chart`]: line charts, one or more panels sharing an x axis, the legend above them.
//! - [`heatmap`]: a grid of values with x/y axes and a colour bar covering every value.
//! - [`format`](mod@format): PNG or JPEG by the file's extension.
//!
//! Every picture carries its own title and axis labels with units, so it reads without the
//! command that wrote it.
//!
//! Legends sit outside the plot area; a heatmap's colour bar covers every value it shows; no
//! file is read at run time (the font is compiled in).

pub mod axes;
pub mod canvas;
pub mod chart;
pub mod format;
pub mod heatmap;
pub mod text;

pub use canvas::Canvas;
pub use chart::{Band, Chart, Panel, Series, Style};
pub use format::Format;
pub use heatmap::Heatmap;
#[cfg(any(test, feature = "internals"))]
pub use heatmap::colormap;
