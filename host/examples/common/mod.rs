//! What the glare probes share: the profile argument and the table of the
//! rows nearest the wall (mean signed and absolute error per frame kind).
#![allow(dead_code)]

use std::collections::BTreeMap;

use spiv_firmware_sim::scene::SceneKind;
use spiv_host::metrics::ProfileRow;

/// `paper-<arg>` for `linear`, `quadratic` or `log` (default quadratic).
pub fn profile(arg: Option<&String>) -> SceneKind {
    let name = arg.map_or("quadratic", String::as_str);
    SceneKind::from_name(&format!("paper-{name}")).unwrap_or(SceneKind::PaperQuadratic)
}

/// Per (frame kind, row height above the wall, px): sums of the signed
/// error, the truth and the absolute error, and the count, over the rows
/// within 90 px of the wall.
#[derive(Default)]
pub struct WallRows(BTreeMap<(usize, i64), (f64, f64, f64, usize)>);

impl WallRows {
    /// Adds kind `i`'s rows.
    pub fn add(&mut self, i: usize, rows: &[ProfileRow]) {
        for r in rows.iter().filter(|r| r.y_wall < 90.0) {
            let e = self.0.entry((i, r.y_wall.round() as i64)).or_default();
            let err = r.measured.unwrap_or(0.0) - r.truth;
            e.0 += err;
            e.1 += r.truth;
            e.2 += err.abs();
            e.3 += 1;
        }
    }

    /// Prints one line per kind and row, kind `i` named `names[i]`.
    pub fn print(&self, names: &[String]) {
        for (&(i, y), &(b, t, a, n)) in &self.0 {
            let k = n.max(1) as f64;
            let name = names.get(i).map_or("?", String::as_str);
            println!(
                "{name:22} y_wall {y}: truth {:.3} mean error {:+.4} mean |error| {:.4}",
                t / k,
                b / k,
                a / k
            );
        }
    }
}
