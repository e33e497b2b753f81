//! The accepted fields of each object of a scene, and the names of its enumerations: the
//! readers refuse every other key, and the schema test compares these tables with
//! `api/scene.schema.json`. Tagged objects list their fields per variant.

pub(super) const TOP_FIELDS: &[&str] = &[
    "$schema",
    "name",
    "domain",
    "mesh",
    "time",
    "boundary",
    "loads",
    "material",
    "friction",
    "smallness",
    "damage",
    "initial",
    "output",
    "error_estimate",
    "solver",
];
pub(super) const DOMAIN_FIELDS: &[&str] = &[
    "width",
    "height",
    "depth",
    "rectangle",
    "mesh",
    "polygon",
    "holes",
];
pub(super) const RECTANGLE_FIELDS: &[&str] = &["width", "height"];
pub(super) const MESH_FIELDS: &[&str] = &["h", "pattern", "refine"];
pub(super) const TIME_FIELDS: &[&str] = &["t_end", "T", "k", "N", "steps"];
pub(super) const PART_VARIANTS: &[(&str, &[&str])] = &[
    ("clamped", &["type", "from", "to", "group", "on", "where"]),
    (
        "traction",
        &["type", "from", "to", "group", "on", "where", "f2"],
    ),
    ("contact", &["type", "from", "to", "group", "on", "where"]),
];
pub(super) const LOADS_FIELDS: &[&str] = &["f0"];
pub(super) const MATERIAL_FIELDS: &[&str] = &["viscosity", "elasticity"];
pub(super) const VISCOSITY_FIELDS: &[&str] = &["eta", "xi"];
pub(super) const ELASTICITY_VARIANTS: &[(&str, &[&str])] = &[
    ("linear", &["type", "mu", "lambda"]),
    ("von_mises", &["type", "eta_b", "sigma_y"]),
];
pub(super) const FRICTION_VARIANTS: &[(&str, &[&str])] = &[
    ("tresca", &["law", "g"]),
    ("slip_weakening", &["law", "mu0", "mu1", "alpha"]),
    ("piecewise_linear", &["law", "points"]),
];
pub(super) const DAMAGE_FIELDS: &[&str] = &["kappa", "source", "zeta0"];
pub(super) const SOURCE_FIELDS: &[&str] = &["a", "b", "zeta_star"];
pub(super) const INITIAL_FIELDS: &[&str] = &["u0"];
pub(super) const OUTPUT_FIELDS: &[&str] = &["every", "last", "fields", "estimate"];
pub(super) const OUTPUT_FIELD_NAMES: &[&str] = &["u", "w", "zeta", "sigma", "von_mises", "contact"];
pub(super) const PATTERNS: &[&str] = &["diagonal", "anti_diagonal", "cross"];
pub(super) const SMALLNESS: &[&str] = &["refuse", "warn"];
pub(super) const SOLVER_FIELDS: &[&str] = &["linear", "precision"];
