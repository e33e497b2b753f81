//! The study report as an SVG picture: errors at t = T against h (or k) on log-log axes with
//! slope-1 and slope-2 guides, and the work–precision diagram (error against wall time).
//! Plain SVG 1.1 text, no fonts or scripts, so it renders the same in browsers and viewers.

use super::format::fraction;
use crate::study::adapt::AdaptResult;
use crate::study::{StudyResult, TargetResult, Vary};
use std::fmt::Write;

const W: f64 = 980.0;
const H: f64 = 470.0;
const PANEL_W: f64 = 400.0;
const PANEL_H: f64 = 300.0;
const TOP: f64 = 70.0;
const LEFTS: [f64; 2] = [80.0, 560.0];
const COLOR_W: &str = "#1f77b4";
const COLOR_Z: &str = "#d62728";

/// Log-scaled axis over whole decades containing the data.
struct LogAxis {
    lo: f64,
    hi: f64,
}

impl LogAxis {
    fn over(values: impl Iterator<Item = f64>) -> LogAxis {
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for v in values.filter(|v| *v > 0.0 && v.is_finite()) {
            lo = lo.min(v.log10());
            hi = hi.max(v.log10());
        }
        if !lo.is_finite() {
            (lo, hi) = (-1.0, 0.0);
        }
        let (lo, hi) = (lo.floor(), hi.ceil());
        LogAxis {
            lo,
            hi: if hi > lo { hi } else { lo + 1.0 },
        }
    }

    /// Position in [0, 1] of a positive value.
    fn frac(&self, v: f64) -> f64 {
        (v.log10() - self.lo) / (self.hi - self.lo)
    }
}

struct Panel {
    left: f64,
    x: LogAxis,
    y: LogAxis,
}

impl Panel {
    fn px(&self, v: f64) -> f64 {
        self.left + self.x.frac(v) * PANEL_W
    }
    fn py(&self, v: f64) -> f64 {
        TOP + PANEL_H - self.y.frac(v) * PANEL_H
    }

    fn frame(&self, out: &mut String, title: &str, xlabel: &str) {
        let (l, b) = (self.left, TOP + PANEL_H);
        let _ = write!(
            out,
            r##"<rect x="{l}" y="{TOP}" width="{PANEL_W}" height="{PANEL_H}" fill="none" stroke="#444"/>
<text x="{}" y="{}" text-anchor="middle" font-size="15">{}</text>
<text x="{}" y="{}" text-anchor="middle" font-size="13">{}</text>
<text x="{}" y="{}" text-anchor="middle" font-size="13" transform="rotate(-90 {} {})">relative error</text>
"##,
            l + PANEL_W / 2.0,
            TOP - 12.0,
            esc(title),
            l + PANEL_W / 2.0,
            b + 40.0,
            esc(xlabel),
            l - 55.0,
            TOP + PANEL_H / 2.0,
            l - 55.0,
            TOP + PANEL_H / 2.0,
        );
        for (axis, horizontal) in [(&self.x, true), (&self.y, false)] {
            let mut e = axis.lo;
            while e <= axis.hi + 1e-9 {
                let f = (e - axis.lo) / (axis.hi - axis.lo);
                let label = format!("1e{e:.0}");
                if horizontal {
                    let x = l + f * PANEL_W;
                    let _ = writeln!(
                        out,
                        r##"<line x1="{x:.1}" y1="{TOP}" x2="{x:.1}" y2="{b}" stroke="#ddd"/><text x="{x:.1}" y="{:.1}" text-anchor="middle" font-size="11">{label}</text>"##,
                        b + 16.0
                    );
                } else {
                    let y = b - f * PANEL_H;
                    let _ = writeln!(
                        out,
                        r##"<line x1="{l}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="#ddd"/><text x="{:.1}" y="{:.1}" text-anchor="end" font-size="11">{label}</text>"##,
                        l + PANEL_W,
                        l - 6.0,
                        y + 4.0
                    );
                }
                e += 1.0;
            }
        }
    }

    /// A polyline with markers through the positive points.
    fn series(&self, out: &mut String, pts: &[(f64, f64)], color: &str, square: bool) {
        let pts: Vec<(f64, f64)> = pts
            .iter()
            .filter(|(x, y)| *x > 0.0 && *y > 0.0 && x.is_finite() && y.is_finite())
            .map(|&(x, y)| (self.px(x), self.py(y)))
            .collect();
        let path: Vec<String> = pts.iter().map(|(x, y)| format!("{x:.1},{y:.1}")).collect();
        let _ = writeln!(
            out,
            r#"<polyline points="{}" fill="none" stroke="{color}" stroke-width="1.5"/>"#,
            path.join(" ")
        );
        for (x, y) in pts {
            if square {
                let _ = writeln!(
                    out,
                    r#"<rect x="{:.1}" y="{:.1}" width="7" height="7" fill="{color}"/>"#,
                    x - 3.5,
                    y - 3.5
                );
            } else {
                let _ = writeln!(
                    out,
                    r#"<circle cx="{x:.1}" cy="{y:.1}" r="4" fill="{color}"/>"#
                );
            }
        }
    }

    /// Dashed line of slope `p` (in decades per decade) through (x0, y0), clipped to the frame.
    fn slope(&self, out: &mut String, p: f64, x0: f64, y0: f64) {
        let (xa, xb) = (10f64.powf(self.x.lo), 10f64.powf(self.x.hi));
        let y = |x: f64| y0 * (x / x0).powf(p);
        // Clip in log space against the y range.
        let (ylo, yhi) = (10f64.powf(self.y.lo), 10f64.powf(self.y.hi));
        let clip_x = |yv: f64| x0 * (yv / y0).powf(1.0 / p);
        let x1 = xa.max(clip_x(ylo));
        let x2 = xb.min(clip_x(yhi));
        if x2 <= x1 {
            return;
        }
        // The guides meet at the anchor: label the steeper one at its upper end and the
        // other at its lower end so the labels never overlap.
        let label = if p > 1.5 {
            (self.px(x2) - 48.0, self.py(y(x2)) + 14.0)
        } else {
            (self.px(x1) + 6.0, self.py(y(x1)) - 6.0)
        };
        let _ = writeln!(
            out,
            r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#888" stroke-dasharray="6 4"/><text x="{:.1}" y="{:.1}" font-size="11" fill="#555">slope {p}</text>"##,
            self.px(x1),
            self.py(y(x1)),
            self.px(x2),
            self.py(y(x2)),
            label.0,
            label.1,
        );
    }
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The two-panel report of a study.
pub fn study_report(s: &StudyResult) -> String {
    let (pname, param): (&str, fn(&crate::study::StudyRow) -> f64) = match s.vary {
        Vary::K => ("time step k", |r| r.k),
        Vary::H => ("mesh size h", |r| r.h),
        Vary::Both => ("mesh size h (k refined with h)", |r| r.h),
    };
    let errs = || s.rows.iter().flat_map(|r| [r.err_w, r.err_zeta]);
    let y = LogAxis::over(errs());
    let left = Panel {
        left: LEFTS[0],
        x: LogAxis::over(s.rows.iter().map(param)),
        y: LogAxis::over(errs()),
    };
    let right = Panel {
        left: LEFTS[1],
        x: LogAxis::over(s.rows.iter().map(|r| r.seconds)),
        y,
    };
    let mut out = format!(
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif">
<title>{}</title>
<rect width="{W}" height="{H}" fill="white"/>
<text x="{}" y="24" text-anchor="middle" font-size="17">{}: reference h = {}, k = {}, |w|_V = {:.5}, |ζ|_Z0 = {:.5}</text>
"##,
        esc(&s.name),
        W / 2.0,
        esc(&s.name),
        fraction(s.reference.h),
        fraction(s.reference.k),
        s.reference.w_v,
        s.reference.zeta_z0,
    );
    left.frame(&mut out, &format!("error at t = T vs {pname}"), pname);
    right.frame(&mut out, "work–precision", "wall time per run [s]");
    let w_pts: Vec<(f64, f64)> = s.rows.iter().map(|r| (param(r), r.err_w)).collect();
    let z_pts: Vec<(f64, f64)> = s.rows.iter().map(|r| (param(r), r.err_zeta)).collect();
    // Guides through the finest level, where the asymptotic order is expected to show.
    if let Some(&(x0, y0)) = w_pts.iter().rev().find(|(x, y)| *x > 0.0 && *y > 0.0) {
        left.slope(&mut out, 1.0, x0, y0);
        left.slope(&mut out, 2.0, x0, y0);
    }
    left.series(&mut out, &w_pts, COLOR_W, false);
    left.series(&mut out, &z_pts, COLOR_Z, true);
    let tw: Vec<(f64, f64)> = s.rows.iter().map(|r| (r.seconds, r.err_w)).collect();
    let tz: Vec<(f64, f64)> = s.rows.iter().map(|r| (r.seconds, r.err_zeta)).collect();
    right.series(&mut out, &tw, COLOR_W, false);
    right.series(&mut out, &tz, COLOR_Z, true);
    let ly = H - 22.0;
    let order = |o: Option<f64>| o.map_or("–".to_string(), |v| format!("{v:.2}"));
    let _ = write!(
        out,
        r##"<circle cx="90" cy="{ly}" r="4" fill="{COLOR_W}"/><text x="100" y="{:.0}" font-size="13">w (velocity), |·|_V, least-squares order {}</text>
<rect x="436.5" y="{:.1}" width="7" height="7" fill="{COLOR_Z}"/><text x="450" y="{:.0}" font-size="13">ζ (damage), |·|_Z0, least-squares order {}</text>
</svg>
"##,
        ly + 4.0,
        order(s.lsq_order_w),
        ly - 3.5,
        ly + 4.0,
        order(s.lsq_order_zeta),
    );
    out
}

/// The work–precision plot of a target study: the predicted frontier of the (h, k) grid
/// within the limits (time against predicted error), the pilot runs (measured time, the
/// model's error at their (h, k)), the target and target/safety lines, and the chosen run
/// twice: predicted (open) and measured time with its estimated error (filled).
pub fn target_report(r: &TargetResult) -> String {
    const COLOR_F: &str = "#888888";
    const COLOR_P: &str = "#2ca02c";
    let m = &r.error_model;
    let pilots: Vec<(f64, f64)> = r
        .pilots
        .iter()
        .map(|p| (p.seconds, m.predict(p.h, p.k)))
        .collect();
    let frontier: Vec<(f64, f64)> = r
        .frontier
        .iter()
        .map(|c| (c.predicted_seconds, c.predicted_error))
        .collect();
    let chosen: Vec<(f64, f64, f64, f64)> = r
        .attempts
        .iter()
        .map(|a| {
            (
                a.predicted_seconds,
                a.predicted_error,
                a.seconds,
                a.estimated_error,
            )
        })
        .collect();
    let xs = pilots
        .iter()
        .chain(&frontier)
        .map(|p| p.0)
        .chain(chosen.iter().flat_map(|c| [c.0, c.2]))
        .collect::<Vec<_>>();
    let ys = pilots
        .iter()
        .chain(&frontier)
        .map(|p| p.1)
        .chain(chosen.iter().flat_map(|c| [c.1, c.3]))
        .chain([r.target_error, r.target_error / r.safety_factor])
        .collect::<Vec<_>>();
    // The frontier reaches far beyond the choice: keep the axes to one decade past it.
    let x_cap = xs
        .iter()
        .copied()
        .filter(|x| *x > 0.0)
        .fold(0.0f64, f64::max)
        .min(10.0 * chosen.iter().map(|c| c.0.max(c.2)).fold(0.0, f64::max));
    let panel = Panel {
        left: LEFTS[0] + 120.0,
        x: LogAxis::over(xs.iter().copied().filter(|x| *x <= x_cap)),
        y: LogAxis::over(ys.iter().copied()),
    };
    let inside = |(x, y): &(f64, f64)| {
        *x <= 10f64.powf(panel.x.hi) && *y >= 10f64.powf(panel.y.lo) && *y <= 10f64.powf(panel.y.hi)
    };
    let frac = fraction;
    let c = &r.chosen;
    let mut out = format!(
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif">
<title>{}</title>
<rect width="{W}" height="{H}" fill="white"/>
<text x="{}" y="24" text-anchor="middle" font-size="17">{}: target {} in {} → h = {}, k = {} (estimated {:.3e}, {:.2} s)</text>
"##,
        esc(&r.name),
        W / 2.0,
        esc(&r.name),
        r.target_error,
        r.quantity.name(),
        frac(c.h),
        frac(c.k),
        c.estimated_error,
        c.seconds,
    );
    let _ = writeln!(
        out,
        r#"<text x="{}" y="42" text-anchor="middle" font-size="12">meshes: {} ({})</text>"#,
        W / 2.0,
        r.meshes.taken,
        esc(&r.meshes.reason)
    );
    panel.frame(
        &mut out,
        "work–precision (predicted frontier, pilots, chosen run)",
        "wall time [s]",
    );
    target_lines(&mut out, &panel, r.target_error, r.safety_factor);
    let frontier: Vec<(f64, f64)> = frontier.into_iter().filter(inside).collect();
    panel.series(&mut out, &frontier, COLOR_F, false);
    for p in pilots.iter().filter(|p| inside(p)) {
        let _ = writeln!(
            out,
            r#"<rect x="{:.1}" y="{:.1}" width="7" height="7" fill="{COLOR_P}"/>"#,
            panel.px(p.0) - 3.5,
            panel.py(p.1) - 3.5
        );
    }
    // Each level of the walk, named; the last (the one whose fields are served) is
    // `chosen-run`, the others `attempt-1`, `attempt-2`, … in the order they ran.
    for (i, (&(tp, ep, tm, em), a)) in chosen.iter().zip(&r.attempts).enumerate() {
        let id = if i + 1 == chosen.len() {
            "chosen-run".to_string()
        } else {
            format!("attempt-{}", i + 1)
        };
        let _ = writeln!(
            out,
            r#"<g id="{id}"><title>h = {}, k = {}: predicted error {:.3e} in {:.3} s, estimated {:.3e} in {:.3} s</title><line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="{COLOR_W}" stroke-dasharray="3 3"/><circle cx="{:.1}" cy="{:.1}" r="7" fill="none" stroke="{COLOR_W}" stroke-width="2"/><circle class="measured" cx="{:.1}" cy="{:.1}" r="7" fill="{COLOR_W}"/></g>"#,
            frac(a.h),
            frac(a.k),
            ep,
            tp,
            em,
            tm,
            panel.px(tp),
            panel.py(ep),
            panel.px(tm),
            panel.py(em),
            panel.px(tp),
            panel.py(ep),
            panel.px(tm),
            panel.py(em),
        );
    }
    let ly = H - 22.0;
    let _ = write!(
        out,
        r##"<circle cx="90" cy="{ly}" r="4" fill="{COLOR_F}"/><text x="100" y="{:.0}" font-size="13">predicted frontier</text>
<rect x="236.5" y="{:.1}" width="7" height="7" fill="{COLOR_P}"/><text x="250" y="{:.0}" font-size="13">pilot runs (model error)</text>
<circle cx="450" cy="{ly}" r="6" fill="none" stroke="{COLOR_W}" stroke-width="2"/><text x="462" y="{:.0}" font-size="13">chosen: predicted</text>
<circle cx="610" cy="{ly}" r="6" fill="{COLOR_W}"/><text x="622" y="{:.0}" font-size="13">chosen: measured time, (2h, 2k) error bar</text>
</svg>
"##,
        ly + 4.0,
        ly - 3.5,
        ly + 4.0,
        ly + 4.0,
        ly + 4.0,
    );
    out
}

/// The target and target / safety lines of a target report, labelled at the panel's right:
/// "target" above its line and "target / safety" (the lower error, the lower line) below
/// its own, so the two labels never overlap however close the lines are.
fn target_lines(out: &mut String, panel: &Panel, target: f64, safety_factor: f64) {
    for (level, dash, label, dy) in [
        (target, "8 4", "target", -4.0),
        (target / safety_factor, "2 3", "target / safety", 12.0),
    ] {
        let y = panel.py(level);
        let _ = writeln!(
            out,
            r##"<line x1="{}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="{COLOR_Z}" stroke-dasharray="{dash}"/><text x="{}" y="{:.1}" font-size="11" fill="{COLOR_Z}">{label}</text>"##,
            panel.left,
            panel.left + PANEL_W,
            panel.left + PANEL_W + 6.0,
            y + dy
        );
    }
}

/// The report of an adaptive study: the relative estimate (circles) and the true error
/// (squares, with a reference) of the cycles (blue) and of the uniform line (grey) against
/// the unknowns, with a slope −1/2 guide (the order of P1 on a smooth solution in 2D;
/// −1/3 in 3D), and against the wall time of each run.
pub fn adapt_report(r: &AdaptResult) -> String {
    const COLOR_U: &str = "#888888";
    let rows = || r.cycles.iter().chain(&r.uniform);
    let ys = || rows().flat_map(|c| [Some(c.estimate), c.error]).flatten();
    let left = Panel {
        left: LEFTS[0],
        x: LogAxis::over(rows().map(|c| c.unknowns as f64)),
        y: LogAxis::over(ys()),
    };
    let right = Panel {
        left: LEFTS[1],
        x: LogAxis::over(rows().map(|c| c.seconds)),
        y: LogAxis::over(ys()),
    };
    let last = r.cycles.last().expect("an adaptive study has a cycle");
    let mut out = format!(
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{W}" height="{H}" viewBox="0 0 {W} {H}" font-family="sans-serif">
<title>{}</title>
<rect width="{W}" height="{H}" fill="white"/>
<text x="{}" y="24" text-anchor="middle" font-size="17">{}: target {:.3e}, {} after {} cycles ({} unknowns, estimate {:.3e})</text>
"##,
        esc(&r.name),
        W / 2.0,
        esc(&r.name),
        r.target,
        if r.reached { "reached" } else { "not reached" },
        r.cycles.len(),
        last.unknowns,
        last.estimate,
    );
    left.frame(
        &mut out,
        "estimate and error vs unknowns",
        "velocity unknowns",
    );
    right.frame(&mut out, "work–precision", "wall time per run [s]");
    let dim_order = match r.final_mesh.dim() {
        2 => -0.5,
        _ => -1.0 / 3.0,
    };
    let pick = |rows: &[super::adapt::Row], x: fn(&super::adapt::Row) -> f64, err: bool| {
        rows.iter()
            .filter_map(|c| Some((x(c), if err { c.error? } else { c.estimate })))
            .collect::<Vec<_>>()
    };
    let unknowns = |c: &super::adapt::Row| c.unknowns as f64;
    let seconds = |c: &super::adapt::Row| c.seconds;
    if let Some(&(x0, y0)) = pick(&r.cycles, unknowns, false).last() {
        left.slope(&mut out, dim_order, x0, y0);
    }
    for (panel, x) in [(&left, unknowns as fn(&_) -> f64), (&right, seconds)] {
        panel.series(&mut out, &pick(&r.uniform, x, false), COLOR_U, false);
        panel.series(&mut out, &pick(&r.uniform, x, true), COLOR_U, true);
        panel.series(&mut out, &pick(&r.cycles, x, false), COLOR_W, false);
        panel.series(&mut out, &pick(&r.cycles, x, true), COLOR_W, true);
    }
    let ly = H - 22.0;
    let _ = write!(
        out,
        r##"<circle cx="90" cy="{ly}" r="4" fill="{COLOR_W}"/><text x="100" y="{:.0}" font-size="13">adaptive cycles</text>
<circle cx="250" cy="{ly}" r="4" fill="{COLOR_U}"/><text x="260" y="{:.0}" font-size="13">uniform refinement</text>
<circle cx="440" cy="{ly}" r="4" fill="#444"/><text x="450" y="{:.0}" font-size="13">relative estimate of w</text>
<rect x="636.5" y="{:.1}" width="7" height="7" fill="#444"/><text x="650" y="{:.0}" font-size="13">true error (against the reference)</text>
</svg>
"##,
        ly + 4.0,
        ly + 4.0,
        ly + 4.0,
        ly - 3.5,
        ly + 4.0,
    );
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The two labels stay 11 px fonts apart (more than a line of text) for any safety
    /// factor, 1 included.
    #[test]
    fn target_labels_do_not_overlap() {
        let p = Panel {
            left: 0.0,
            x: LogAxis { lo: -3.0, hi: 0.0 },
            y: LogAxis { lo: -4.0, hi: 0.0 },
        };
        for safety in [1.0, 1.2, 2.0, 10.0] {
            let mut out = String::new();
            target_lines(&mut out, &p, 0.01, safety);
            let ys: Vec<f64> = out
                .match_indices("<text x=\"")
                .map(|(i, _)| {
                    let rest = &out[i..];
                    let at = rest.find(" y=\"").unwrap() + 4;
                    rest[at..].split('"').next().unwrap().parse().unwrap()
                })
                .collect();
            assert_eq!(ys.len(), 2);
            assert!(ys[1] - ys[0] >= 14.0, "safety {safety}: labels at {ys:?}");
        }
    }

    #[test]
    fn fractions_and_axes() {
        assert_eq!(fraction(1.0 / 128.0), "1/128");
        assert_eq!(fraction(0.3), "0.3000");
        let a = LogAxis::over([0.02, 0.5, 0.0, f64::NAN].into_iter());
        assert_eq!((a.lo, a.hi), (-2.0, 0.0));
        assert!((a.frac(0.1) - 0.5).abs() < 1e-12);
        let one = LogAxis::over([1.0].into_iter());
        assert_eq!(
            (one.lo, one.hi),
            (0.0, 1.0),
            "a single decade, never an empty range"
        );
    }

    #[test]
    fn slope_guides_have_the_slope_they_claim() {
        let p = Panel {
            left: 0.0,
            x: LogAxis { lo: -3.0, hi: 0.0 },
            y: LogAxis { lo: -4.0, hi: 0.0 },
        };
        for slope in [1.0, 2.0] {
            let mut out = String::new();
            p.slope(&mut out, slope, 0.1, 0.01);
            let num = |key: &str| -> f64 {
                let at = out.find(&format!("{key}=\"")).unwrap() + key.len() + 2;
                out[at..].split('"').next().unwrap().parse().unwrap()
            };
            let (x1, y1, x2, y2) = (num("x1"), num("y1"), num("x2"), num("y2"));
            // Pixels per decade differ on the two axes: convert back to decades.
            let dx = (x2 - x1) / PANEL_W * 3.0;
            let dy = (y1 - y2) / PANEL_H * 4.0;
            assert!((dy / dx - slope).abs() < 0.01, "slope {slope}: {out}");
        }
    }
}
