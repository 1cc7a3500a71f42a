//! `tessera bench`'s plots: for each scene one PNG of error against time, a panel per
//! sweep (samples per pixel with the quality presets, maximum depth, Russian roulette,
//! motion steps), on log-log axes with each point labelled by its setting.

use std::path::{Path, PathBuf};

use anyhow::{anyhow, Context};
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::bench::{Point, SceneReport, RR_NEVER};

/// Size of one scene's figure (four panels).
pub const WIDTH: u32 = 1200;
pub const HEIGHT: u32 = 900;
/// The family the bundled font is registered as.
const FONT: &str = "sans-serif";

/// One line of a panel: (seconds, error, label) points.
struct Series {
    name: String,
    color: RGBColor,
    points: Vec<(f64, f64, String)>,
    /// Joined by a line (a sweep) or markers only (the presets).
    line: bool,
}

impl Series {
    fn sweep(name: &str, color: RGBColor, points: &[Point], label: impl Fn(u32) -> String) -> Self {
        Series {
            name: name.into(),
            color,
            points: points
                .iter()
                .map(|p| (p.seconds, p.rmse, label(p.value)))
                .collect(),
            line: true,
        }
    }
}

/// The file name of `scene`'s figure, relative to the report's folder.
pub fn plot_path(scene: &str) -> String {
    let name: String = scene
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '-' })
        .collect();
    format!("plots/{name}.png")
}

/// Writes one figure per scene under `dir` (at [`plot_path`]); returns the files written.
pub fn write(dir: &Path, scenes: &[SceneReport]) -> anyhow::Result<Vec<PathBuf>> {
    // ab_glyph draws text only in fonts registered by name; registering again replaces.
    plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular())
        .map_err(|_| anyhow!("the bundled DejaVu Sans font does not load"))?;
    let mut written = Vec::new();
    for scene in scenes {
        let path = dir.join(plot_path(&scene.name));
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)
                .with_context(|| format!("creating {}", parent.display()))?;
        }
        let pixels = figure(scene)?;
        image::RgbImage::from_raw(WIDTH, HEIGHT, pixels)
            .context("the figure's buffer has the figure's size")?
            .save(&path)
            .with_context(|| format!("writing {}", path.display()))?;
        written.push(path);
    }
    Ok(written)
}

/// `scene`'s figure as RGB pixels.
fn figure(scene: &SceneReport) -> anyhow::Result<Vec<u8>> {
    let mut pixels = vec![0u8; (WIDTH * HEIGHT * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut pixels, (WIDTH, HEIGHT)).into_drawing_area();
        root.fill(&WHITE)?;
        let title = format!(
            "{} ({}x{}): RMSE against a {} spp reference, by wall time",
            scene.name, scene.width, scene.height, scene.reference_spp
        );
        let root = root.titled(&title, (FONT, 24))?;
        let panels = root.split_evenly((2, 2));

        let presets = Series {
            name: "quality presets".into(),
            color: RED,
            points: scene
                .presets
                .iter()
                .map(|p| (p.seconds, p.rmse, p.preset.clone()))
                .collect(),
            line: false,
        };
        let spp = Series::sweep("samples per pixel", BLUE, &scene.spp_sweep, |v| {
            format!("{v} spp")
        });
        panel(&panels[0], "samples per pixel", &[spp, presets])?;
        let depth = Series::sweep("maximum depth", BLUE, &scene.depth_sweep, |v| {
            format!("depth {v}")
        });
        panel(
            &panels[1],
            &format!("maximum depth ({} spp)", scene.fixed_spp),
            &[depth],
        )?;
        let rr = Series::sweep("Russian roulette", BLUE, &scene.rr_sweep, |v| {
            if v == RR_NEVER {
                "never".into()
            } else {
                format!("from {v}")
            }
        });
        panel(
            &panels[2],
            &format!("Russian roulette's first bounce ({} spp)", scene.fixed_spp),
            &[rr],
        )?;
        let steps = Series::sweep("motion steps", BLUE, &scene.motion_sweep, |v| {
            format!("{v} steps")
        });
        panel(
            &panels[3],
            &format!(
                "motion steps ({} spp; error against 64 steps)",
                scene.fixed_spp
            ),
            &[steps],
        )?;
        root.present()?;
    }
    Ok(pixels)
}

/// Nice tick labels for a log axis: two significant digits.
fn short(v: &f64) -> String {
    let digits = (1.0 - v.abs().log10().floor()).max(0.0) as usize;
    format!("{v:.digits$}")
}

/// One panel: every series' points on log-log axes that hold them all.
fn panel(
    area: &DrawingArea<BitMapBackend, Shift>,
    title: &str,
    series: &[Series],
) -> anyhow::Result<()> {
    // Log axes hold positive values only (an error of exactly 0 has nothing to plot).
    let points: Vec<(f64, f64)> = series
        .iter()
        .flat_map(|s| s.points.iter().map(|p| (p.0, p.1)))
        .filter(|&(x, y)| x > 0.0 && y > 0.0 && x.is_finite() && y.is_finite())
        .collect();
    if points.is_empty() {
        area.draw(&Text::new(
            format!("{title}: nothing to plot in this scene"),
            (20, 40),
            (FONT, 18),
        ))?;
        return Ok(());
    }
    // Each axis spans at least a decade, so that it holds a power of ten to label.
    let range = |values: Vec<f64>| {
        let lo = values.iter().copied().fold(f64::INFINITY, f64::min) / 1.6;
        let hi = values.iter().copied().fold(0.0, f64::max) * 1.6;
        let widen = (10.0 / (hi / lo)).max(1.0).sqrt();
        (lo / widen)..(hi * widen)
    };
    let x = range(points.iter().map(|p| p.0).collect());
    let y = range(points.iter().map(|p| p.1).collect());
    let mut chart = ChartBuilder::on(area)
        .caption(title, (FONT, 18))
        .margin(12)
        .x_label_area_size(42)
        .y_label_area_size(64)
        .build_cartesian_2d(x.log_scale(), y.log_scale())?;
    chart
        .configure_mesh()
        .x_desc("seconds")
        .y_desc("RMSE")
        // Few ticks and no minor lines: a log axis over a narrow range crowds both.
        .x_labels(6)
        .y_labels(6)
        .light_line_style(TRANSPARENT)
        .x_label_formatter(&short)
        .y_label_formatter(&short)
        .label_style((FONT, 13))
        .draw()?;
    for s in series {
        let color = s.color;
        let kept: Vec<&(f64, f64, String)> = s
            .points
            .iter()
            .filter(|p| p.0 > 0.0 && p.1 > 0.0 && p.0.is_finite() && p.1.is_finite())
            .collect();
        if s.line {
            chart.draw_series(LineSeries::new(kept.iter().map(|p| (p.0, p.1)), color))?;
        }
        chart
            .draw_series(
                kept.iter()
                    .map(|p| Circle::new((p.0, p.1), 4, color.filled())),
            )?
            .label(s.name.clone())
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, color.filled()));
        chart.draw_series(kept.iter().map(|p| {
            EmptyElement::at((p.0, p.1)) + Text::new(p.2.clone(), (6, -16), (FONT, 13))
        }))?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .label_font((FONT, 13))
        .draw()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_keep_two_significant_digits() {
        assert_eq!(short(&0.0021), "0.0021");
        assert_eq!(short(&3.4), "3.4");
        assert_eq!(short(&12.3), "12");
        assert_eq!(short(&250.0), "250");
    }

    #[test]
    fn plot_paths_are_plain_file_names() {
        assert_eq!(plot_path("motion-blur"), "plots/motion-blur.png");
        assert_eq!(plot_path("../a b.glb"), "plots/---a-b-glb.png");
    }
}
