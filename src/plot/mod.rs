//! Pictures for people: [`chart`]s (panels sharing an x axis, the legend above them) and
//! [`heatmap`]s over the build plane, drawn on a [`canvas`] with [`axes`] and the
//! compiled-in font ([`text`]), written as PNG or JPEG ([`format`](mod@format)). Every
//! picture carries its title and axis labels with units.
//!
//! Legends sit outside the plot area; a heatmap's colour bar covers every value it shows; no
//! file is read at run time.

pub mod axes;
pub mod canvas;
pub mod chart;
pub mod format;
pub mod heatmap;
pub mod text;

pub use canvas::Canvas;
pub use chart::{Band, Chart, Panel, Series, Style};
pub use format::Format;
#[cfg(any(test, feature = "internals"))]
pub use heatmap::colormap;
pub use heatmap::Heatmap;
