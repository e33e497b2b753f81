//! The paper's scenes (Han, Jureczka & Ochal 2020, section 4), written out in full.
//!
//! Every field is given explicitly, defaults included, so that `contact-sim preset NAME`
//! prints a complete, self-documenting scene to start from. Common data (docs/src/explanation/numerics.md,
//! "Paper scenes"): T = 1; A and B of (4.1) with η = ξ = 2, μ = λ = 4; u0 = 0; j(ξ) = 20|ξ|;
//! φ of (4.2); κ = 0.5; ζ0 = 1.

use serde_json::{json, Value};

struct Preset {
    name: &'static str,
    description: &'static str,
    build: fn() -> Value,
}

const PRESETS: &[Preset] = &[
    Preset {
        name: "paper-exp1",
        description: "Experiment 1: Ω = (0,2)×(0,1) clamped on the left, pushed down by the body \
                      force f0 = (0, −0.2); no contact; h = k = 1/32.",
        build: exp1,
    },
    Preset {
        name: "paper-exp2",
        description: "Experiment 2: as experiment 1 with frictional contact on [0,1]×{0} and \
                      f0 = (0, −0.8); h = k = 1/32.",
        build: exp2,
    },
    Preset {
        name: "paper-exp3",
        description: "Experiment 3: contact on the whole bottom [0,2]×{0}, traction \
                      f2 = (−1, −1) on the top and right sides, f0 = 0; h = k = 1/32.",
        build: exp3,
    },
    Preset {
        name: "paper-convergence",
        description: "Convergence test: Ω = (0,1)², contact on the bottom, traction \
                      f2 = (−1.4, −0.2) on the top and right; the paper's reference run \
                      h = k = 1/128. This scheme gives |w|_V = 0.1528, |ζ|_Z0 = 0.7639 there; \
                      the paper prints 0.23525 and 0.75375, which no variant of the printed \
                      scheme reproduces (README, \"Reproduce the paper\"); its orders agree.",
        build: convergence,
    },
    Preset {
        name: "plate-with-hole",
        description: "A 2×1 plate with an off-centre hole (r = 0.2 at (0.7, 0.45)), imported from \
                      gmsh: clamped on the left, frictional contact on the bottom with a low \
                      bound g = 1 so part of Γ3 slips, traction f2 = (−1, −1) on the top; \
                      paper material and damage; k = 1/32.",
        build: plate_with_hole,
    },
    Preset {
        name: "arch-on-support",
        description: "An arch (annulus sector 1 ≤ r ≤ 1.5, 0°–120°) imported from gmsh, in \
                      bilateral frictional contact along its inner arc (a curved Γ3 with \
                      rotated frames), clamped at its end on y = 0, pressed by f2 = (0, −1) \
                      on the outer arc; g = 1; k = 1/32.",
        build: arch_on_support,
    },
    Preset {
        name: "l-bracket",
        description: "An L-shaped bracket (2×1 with the upper right quarter 1×0.5 cut away) \
                      given as a polygon and meshed in-process at h = 1/16: clamped on x = 0, \
                      frictional contact (g = 0.3, part of Γ3 slips) on y = 0, pressed by f2 = (−0.5, −1) on the \
                      step y = 0.5, x ≥ 1; parts selected by formulas; k = 1/32.",
        build: l_bracket,
    },
    Preset {
        name: "box-exp3",
        description: "Experiment 3 in 3D: the box (0,2)×(0,1)×(0,1) of Kuhn tetrahedra, clamped \
                      on x = 0, frictional contact on the bottom z = 0, traction \
                      f2 = (−1, 0, −1) on the top z = 1 and the end x = 2; paper material, \
                      damage and g = 20; h = k = 1/8.",
        build: box_exp3,
    },
    Preset {
        name: "box-convergence",
        description: "The convergence test in 3D: the unit cube, clamped on x = 0, contact on \
                      z = 0, traction f2 = (−1.4, 0, −0.2) on x = 1 and z = 1; h = k = 1/16 \
                      (the reference of the 3D study h = 1/2, 1/4, 1/8).",
        build: box_convergence,
    },
    Preset {
        name: "standing-cylinder",
        description: "A cylinder (r = 0.5, height 1.5) of tetrahedra imported from gmsh, standing \
                      on its base: frictional contact on the base z = 0 (g = 1), held at its \
                      top, pushed sideways by f2 = (−1, 0, 0) on the half x ≥ 0 of its side; \
                      paper material and damage; k = 1/16.",
        build: standing_cylinder,
    },
];

/// The meshes the presets import, bundled into the binary (generated once with gmsh by
/// `crates/contact-core/tests/meshes/generate.py` and `generate_standing_cylinder.py`).
const BUNDLED: &[(&str, &[u8])] = &[
    (
        "plate-with-hole.msh",
        include_bytes!("../../preset-meshes/plate-with-hole.msh"),
    ),
    (
        "arch-on-support.msh",
        include_bytes!("../../preset-meshes/arch-on-support.msh"),
    ),
    (
        "standing-cylinder.msh",
        include_bytes!("../../preset-meshes/standing-cylinder.msh"),
    ),
];

/// The bytes of a mesh bundled with the presets.
pub fn bundled_mesh(name: &str) -> Option<&'static [u8]> {
    BUNDLED.iter().find(|(n, _)| *n == name).map(|(_, b)| *b)
}

/// The preset names, in presentation order.
pub fn names() -> &'static [&'static str] {
    const NAMES: &[&str] = &[
        "paper-exp1",
        "paper-exp2",
        "paper-exp3",
        "paper-convergence",
        "plate-with-hole",
        "arch-on-support",
        "l-bracket",
        "box-exp3",
        "box-convergence",
        "standing-cylinder",
    ];
    NAMES
}

/// One line describing a preset.
pub fn description(name: &str) -> Option<&'static str> {
    find(name).map(|p| p.description)
}

/// The full scene document of a preset.
pub fn get(name: &str) -> Option<Value> {
    find(name).map(|p| (p.build)())
}

fn find(name: &str) -> Option<&'static Preset> {
    PRESETS.iter().find(|p| p.name == name)
}

/// Whole numbers are written as JSON integers ([0, 1], not [0.0, 1.0]): the printed presets
/// are meant to be read and edited.
fn num(x: f64) -> Value {
    if x.fract() == 0.0 && x.abs() < 1e15 {
        json!(x as i64)
    } else {
        json!(x)
    }
}

fn vector(v: [f64; 2]) -> Value {
    json!([num(v[0]), num(v[1])])
}

fn segment(kind: &str, from: [f64; 2], to: [f64; 2]) -> Value {
    json!({"type": kind, "from": vector(from), "to": vector(to)})
}

fn traction(from: [f64; 2], to: [f64; 2], f2: [f64; 2]) -> Value {
    json!({"type": "traction", "from": vector(from), "to": vector(to), "f2": vector(f2)})
}

/// The fields every paper scene shares; `boundary`, `loads` and the geometry vary.
fn paper_scene(
    name: &str,
    (width, height): (f64, f64),
    hk: &str,
    boundary: Vec<Value>,
    f0: [f64; 2],
) -> Value {
    json!({
        "name": name,
        "domain": {"width": num(width), "height": num(height)},
        "mesh": {"h": hk, "pattern": "diagonal"},
        "time": {"t_end": 1, "k": hk},
        "boundary": boundary,
        "loads": {"f0": vector(f0)},
        "material": {
            "viscosity": {"eta": 2, "xi": 2},
            "elasticity": {"type": "linear", "mu": 4, "lambda": 4}
        },
        "friction": {"law": "tresca", "g": 20},
        "smallness": "refuse",
        "damage": {
            "kappa": 0.5,
            "source": {"a": 2, "b": 20, "zeta_star": 0.2},
            "zeta0": 1
        },
        "initial": {"u0": [0, 0]},
        "output": {
            "every": 1,
            "last": true,
            "fields": ["u", "w", "zeta", "sigma", "von_mises", "contact"]
        }
    })
}

fn exp1() -> Value {
    paper_scene(
        "paper-exp1",
        (2.0, 1.0),
        "1/32",
        vec![
            segment("clamped", [0.0, 0.0], [0.0, 1.0]),
            traction([0.0, 1.0], [2.0, 1.0], [0.0, 0.0]),
            traction([2.0, 0.0], [2.0, 1.0], [0.0, 0.0]),
            traction([0.0, 0.0], [2.0, 0.0], [0.0, 0.0]),
        ],
        [0.0, -0.2],
    )
}

fn exp2() -> Value {
    paper_scene(
        "paper-exp2",
        (2.0, 1.0),
        "1/32",
        vec![
            segment("clamped", [0.0, 0.0], [0.0, 1.0]),
            segment("contact", [0.0, 0.0], [1.0, 0.0]),
            traction([0.0, 1.0], [2.0, 1.0], [0.0, 0.0]),
            traction([2.0, 0.0], [2.0, 1.0], [0.0, 0.0]),
            traction([1.0, 0.0], [2.0, 0.0], [0.0, 0.0]),
        ],
        [0.0, -0.8],
    )
}

fn exp3() -> Value {
    paper_scene(
        "paper-exp3",
        (2.0, 1.0),
        "1/32",
        vec![
            segment("clamped", [0.0, 0.0], [0.0, 1.0]),
            segment("contact", [0.0, 0.0], [2.0, 0.0]),
            traction([0.0, 1.0], [2.0, 1.0], [-1.0, -1.0]),
            traction([2.0, 0.0], [2.0, 1.0], [-1.0, -1.0]),
        ],
        [0.0, 0.0],
    )
}

fn convergence() -> Value {
    paper_scene(
        "paper-convergence",
        (1.0, 1.0),
        "1/128",
        vec![
            segment("clamped", [0.0, 0.0], [0.0, 1.0]),
            segment("contact", [0.0, 0.0], [1.0, 0.0]),
            traction([0.0, 1.0], [1.0, 1.0], [-1.4, -0.2]),
            traction([1.0, 0.0], [1.0, 1.0], [-1.4, -0.2]),
        ],
        [0.0, 0.0],
    )
}

/// A paper scene on the box [0, width] × [0, height] × [0, depth]: clamped on x = 0, contact
/// on z = 0, traction f2 on the top z = depth and the end x = width.
fn box_scene(name: &str, (width, height, depth): (f64, f64, f64), hk: &str, f2: [f64; 3]) -> Value {
    let f2 = json!([num(f2[0]), num(f2[1]), num(f2[2])]);
    let mut doc = paper_scene(name, (width, height), hk, Vec::new(), [0.0, 0.0]);
    doc["domain"] = json!({"width": num(width), "height": num(height), "depth": num(depth)});
    doc["mesh"] = json!({"h": hk});
    doc["boundary"] = json!([
        {"type": "clamped", "on": "x"},
        {"type": "contact", "on": "z"},
        {"type": "traction", "on": format!("z - {}", num(depth)), "f2": f2},
        {"type": "traction", "on": format!("x - {}", num(width)), "f2": f2},
    ]);
    doc["loads"] = json!({"f0": [0, 0, 0]});
    doc["initial"] = json!({"u0": [0, 0, 0]});
    doc
}

fn box_exp3() -> Value {
    box_scene("box-exp3", (2.0, 1.0, 1.0), "1/8", [-1.0, 0.0, -1.0])
}

fn box_convergence() -> Value {
    box_scene(
        "box-convergence",
        (1.0, 1.0, 1.0),
        "1/16",
        [-1.4, 0.0, -0.2],
    )
}

/// A preset on a bundled gmsh mesh: the paper's material and damage, Tresca bound g.
fn imported(name: &str, file: &str, boundary: Vec<Value>, g: f64) -> Value {
    let mut doc = paper_scene(name, (1.0, 1.0), "1/32", boundary, [0.0, 0.0]);
    doc["domain"] = json!({"mesh": file});
    doc["mesh"] = json!({"refine": 0});
    doc["friction"] = json!({"law": "tresca", "g": num(g)});
    doc
}

fn plate_with_hole() -> Value {
    imported(
        "plate-with-hole",
        "plate-with-hole.msh",
        vec![
            json!({"type": "clamped", "group": "clamped"}),
            json!({"type": "contact", "group": "contact"}),
            json!({"type": "traction", "group": "traction", "f2": [-1, -1]}),
        ],
        0.5,
    )
}

fn arch_on_support() -> Value {
    imported(
        "arch-on-support",
        "arch-on-support.msh",
        vec![
            json!({"type": "clamped", "group": "clamped"}),
            json!({"type": "contact", "on": "x^2 + y^2 - 1"}),
            json!({"type": "traction", "group": "outer", "f2": [0, -1]}),
        ],
        1.0,
    )
}

fn standing_cylinder() -> Value {
    let mut doc = imported(
        "standing-cylinder",
        "standing-cylinder.msh",
        vec![
            json!({"type": "clamped", "group": "top"}),
            json!({"type": "contact", "group": "base"}),
            json!({"type": "traction", "on": "x^2 + y^2 - 0.25", "where": "x", "f2": [-1, 0, 0]}),
        ],
        1.0,
    );
    doc["time"]["k"] = json!("1/16");
    doc["loads"] = json!({"f0": [0, 0, 0]});
    doc["initial"] = json!({"u0": [0, 0, 0]});
    doc
}

fn l_bracket() -> Value {
    let mut doc = paper_scene(
        "l-bracket",
        (1.0, 1.0),
        "1/32",
        vec![
            json!({"type": "clamped", "on": "x"}),
            json!({"type": "contact", "on": "y"}),
            json!({"type": "traction", "on": "y - 0.5", "where": "x - 1", "f2": [-0.5, -1]}),
        ],
        [0.0, 0.0],
    );
    doc["domain"] = json!({"polygon": [[0, 0], [2, 0], [2, 0.5], [1, 0.5], [1, 1], [0, 1]]});
    doc["mesh"] = json!({"h": "1/16", "refine": 0});
    doc["friction"] = json!({"law": "tresca", "g": 0.3});
    doc
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::problem::{BoundaryKind, FrictionLaw};
    use crate::scene::validate;

    #[test]
    fn names_and_table_agree() {
        let table: Vec<&str> = PRESETS.iter().map(|p| p.name).collect();
        assert_eq!(names(), table.as_slice());
        for name in names() {
            assert!(description(name).is_some_and(|d| !d.is_empty()));
            assert_eq!(get(name).unwrap()["name"], *name);
        }
        assert!(get("paper-exp4").is_none());
        assert_eq!(
            get("paper-exp3").unwrap()["boundary"][0]["to"],
            json!([0, 1])
        );
        assert!(description("nope").is_none());
    }

    #[test]
    fn every_preset_validates() {
        for name in names() {
            let doc = get(name).unwrap();
            let p = validate(&doc).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(p.name, *name);
            assert_eq!(p.t_end, 1.0);
            let g = match *name {
                "plate-with-hole" => 0.5,
                "arch-on-support" => 1.0,
                "l-bracket" => 0.3,
                "standing-cylinder" => 1.0,
                _ => 20.0,
            };
            assert_eq!(p.friction, FrictionLaw::Tresca { g });
            assert!(p.damage.is_some());
            assert!(p.u0.is_zero());
        }
    }

    #[test]
    fn paper_values() {
        let p = validate(&get("paper-exp1").unwrap()).unwrap();
        assert_eq!((p.steps, p.cells_per_unit, p.cells()), (32, 32, (64, 32)));
        assert_eq!(p.boundary.len(), 4);
        assert!(!p
            .boundary
            .iter()
            .any(|b| matches!(b.kind, BoundaryKind::Contact)));
        assert_eq!(p.body_force.eval(1.0, 0.5, 0.3), [0.0, -0.2]);

        let p = validate(&get("paper-exp2").unwrap()).unwrap();
        assert_eq!(p.boundary.len(), 5);
        assert_eq!(p.body_force.eval(0.0, 0.0, 0.0), [0.0, -0.8]);

        let p = validate(&get("paper-exp3").unwrap()).unwrap();
        assert_eq!(p.boundary.len(), 4);
        assert!(p.body_force.is_zero());
        let tractions: Vec<_> = p
            .boundary
            .iter()
            .filter_map(|b| match &b.kind {
                BoundaryKind::Traction(f) => Some(f.eval(0.0, 0.0, 0.0)),
                _ => None,
            })
            .collect();
        assert_eq!(tractions, vec![[-1.0, -1.0]; 2]);

        let p = validate(&get("paper-convergence").unwrap()).unwrap();
        assert_eq!(
            (p.steps, p.cells_per_unit, p.cells()),
            (128, 128, (128, 128))
        );
        assert_eq!(p.k(), 1.0 / 128.0);
        let damage = p.damage.unwrap();
        assert_eq!(damage.kappa, 0.5);
        assert_eq!(
            (damage.source.a, damage.source.b, damage.source.zeta_star),
            (2.0, 20.0, 0.2)
        );
    }
}
