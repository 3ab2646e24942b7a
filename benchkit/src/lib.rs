//! `softsync-benchkit`: what softsync's benchmarks share, and nothing a product needs:
//! nearest-rank percentiles ([`stats`]), `RESULT` lines and CSV files ([`output`]), line
//! charts as SVG ([`chart`]), progress bars on a terminal ([`progress`]), the thesis's reference tables ([`thesis`]) and recorded
//! soft-body traces ([`trace`]).

pub mod chart;
pub mod output;
pub mod progress;
pub mod rng;
pub mod stats;
pub mod thesis;
pub mod trace;

/// The chart library, for the few one-off charts [`chart`] does not draw.
pub use plotters;

pub use chart::{write_svg, ChartError, ChartStyle, LineChart, Series};
pub use output::{Csv, ResultLine};
pub use progress::Progress;
pub use rng::SplitMix64;
pub use stats::{median, percentile, percentile_of_sorted, Summary};
