//! A reader of gmsh MSH files, versions 4.1 and 2.2 (ASCII and binary, both byte orders),
//! into a neutral mesh structure, for body shapes made with gmsh and imported into scenes.
//!
//! Format pieces read (version 4.1; the sections of 2.2 are in [`v2`]):
//! - `$MeshFormat`: version (4.1 or 2.2; others are refused by name), file type
//!   (0 ASCII, 1 binary), data size (the width of `size_t`, 4 or 8) and, in binary files, the
//!   integer 1 that fixes the byte order.
//! - `$PhysicalNames` (always ASCII): dimension, tag and quoted name of each physical group.
//! - `$Entities`: the physical tags of every point, curve, surface and volume (bounding boxes
//!   and bounding entities are read past).
//! - `$Nodes`: the entity blocks with node tags and x, y, z (parametric u, v, w read past).
//! - `$Elements`: the entity blocks of 2-node lines (type 1), 3-node triangles (type 2) and
//!   4-node tetrahedra (type 4); points (type 15) are read past, so are lines in a 3D mesh.
//!   Other known types of the cell or facet dimension (quadrangles, second-order elements…)
//!   are refused by name, with how to export first-order simplices; unknown types are refused
//!   because their size is unknown.
//! - Any other section (`$Periodic`, `$NodeData`, …) is skipped up to its `$End` line.
//!
//! Output ([`MshMesh`]): the nodes as `[f64; 3]` in file order (their file tags mapped to
//! 0-based indices), the cells of the highest dimension (triangles in 2D, where all z = 0, or
//! tetrahedra in 3D) as index arrays in file order, and the facet elements (lines in 2D,
//! triangles in 3D) grouped by physical group, with the group's tag and its name from
//! `$PhysicalNames`; a facet element in no physical group is left out. The reader checks only
//! the file's consistency; mesh quality (orientation, degenerate cells, connectivity) is the
//! caller's.
//!
//! The input is untrusted: every count from a header is checked against the bytes left
//! before anything is allocated from it, and every failure is a [`MshError`] naming the
//! section and the line and byte offset — never a panic.
//!
//! Written here rather than on the `mshio` crate (0.4.2, last release 2020): a binary header
//! whose data size is not 1, 2, 4, 8 or 16 (e.g. `4.1 1 0`) makes it panic
//! (`unimplemented!` in its integer parser), so every header would have to be parsed before
//! handing the bytes over; it also skips `$PhysicalNames`, which the scenes bind boundary
//! parts to, and it pulls in nom 5 and num 0.3.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt;

#[cfg(test)]
mod tests;
mod v2;

/// At most this many physical groups (named in `$PhysicalNames` or used by entities).
pub const MAX_PHYSICAL_GROUPS: usize = 10_000;

/// A mesh read from an MSH 4.1 or 2.2 file.
#[derive(Debug, Clone, PartialEq)]
pub struct MshMesh {
    /// 2 (triangle cells, all z = 0) or 3 (tetrahedron cells).
    pub dim: usize,
    /// Node coordinates in file order; index i is the node with file tag `node_tags[i]`.
    pub nodes: Vec<[f64; 3]>,
    /// The file tag of each node.
    pub node_tags: Vec<u64>,
    /// The cells, `dim + 1` node indices each, flat and in file order (see [`Self::cells`]).
    pub cell_nodes: Vec<usize>,
    /// The facet groups, by increasing physical tag; only groups of dimension `dim − 1` that
    /// hold at least one facet element.
    pub groups: Vec<FacetGroup>,
    /// Every entry of `$PhysicalNames` (all dimensions), in file order.
    pub physical_names: Vec<PhysicalName>,
}

/// The facet elements of one physical group of dimension `dim − 1`.
#[derive(Debug, Clone, PartialEq)]
pub struct FacetGroup {
    /// The physical tag.
    pub tag: i32,
    /// The name from `$PhysicalNames`, if the file names this group.
    pub name: Option<String>,
    /// The facets, `dim` node indices each, flat and in file order (see [`Self::facets`]).
    pub facet_nodes: Vec<usize>,
    /// Nodes per facet (= the mesh's `dim`).
    pub facet_len: usize,
}

/// One entry of `$PhysicalNames`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PhysicalName {
    pub dim: usize,
    pub tag: i32,
    pub name: String,
}

impl MshMesh {
    /// The cells as slices of `dim + 1` node indices.
    pub fn cells(&self) -> impl Iterator<Item = &[usize]> {
        self.cell_nodes.chunks_exact(self.dim + 1)
    }

    /// The number of cells.
    pub fn cell_count(&self) -> usize {
        self.cell_nodes.len() / (self.dim + 1)
    }

    /// The facet group with this name, if any.
    pub fn group(&self, name: &str) -> Option<&FacetGroup> {
        self.groups.iter().find(|g| g.name.as_deref() == Some(name))
    }
}

impl FacetGroup {
    /// The facets as slices of `facet_len` node indices.
    pub fn facets(&self) -> impl Iterator<Item = &[usize]> {
        self.facet_nodes.chunks_exact(self.facet_len)
    }

    /// The number of facets.
    pub fn len(&self) -> usize {
        self.facet_nodes.len() / self.facet_len
    }

    /// Whether the group holds no facet (never true for a group of a read mesh).
    pub fn is_empty(&self) -> bool {
        self.facet_nodes.is_empty()
    }
}

/// Where in the file something went wrong.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Location {
    /// The section, e.g. `$Nodes`.
    pub section: &'static str,
    /// 1-based line number (counted in newline bytes, also in binary data).
    pub line: usize,
    /// 0-based byte offset.
    pub offset: usize,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "in {} at line {} (byte offset {})",
            self.section, self.line, self.offset
        )
    }
}

/// Why an MSH file was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MshError {
    #[error("not a gmsh MSH file: it must begin with $MeshFormat")]
    NotMsh,
    #[error(
        "MSH version {0} is not supported: versions 4.1 and 2.2 are read (in gmsh, save with Mesh.MshFileVersion = 4.1)"
    )]
    UnsupportedVersion(String),
    #[error("{at}: {what}")]
    BadHeader { at: Location, what: &'static str },
    #[error("{at}: the file ends where {expected} was expected (truncated file)")]
    Truncated {
        at: Location,
        expected: &'static str,
    },
    #[error("{at}: expected {expected}, found {found:?}")]
    Syntax {
        at: Location,
        expected: &'static str,
        found: String,
    },
    #[error("{at}: {what} {count} is more than the remaining {remaining} bytes can hold")]
    HugeCount {
        at: Location,
        what: &'static str,
        count: u64,
        remaining: usize,
    },
    #[error("{at}: {count} {what}, more than the limit of {limit}")]
    TooMany {
        at: Location,
        what: &'static str,
        count: u64,
        limit: usize,
    },
    #[error("{section}: the header declares {declared} {what} but the blocks hold {found}")]
    BadCount {
        section: &'static str,
        what: &'static str,
        declared: u64,
        found: u64,
    },
    #[error("{at}: node {node} has a non-finite coordinate")]
    NonFinite { at: Location, node: u64 },
    #[error("{at}: node tag {node} appears twice")]
    DuplicateNode { at: Location, node: u64 },
    #[error("{at}: tag 0 is reserved and may not be used for {what}")]
    ZeroTag { at: Location, what: &'static str },
    #[error("$Elements: element {element} refers to node {node}, which is not in $Nodes")]
    MissingNode { element: u64, node: u64 },
    #[error(
        "{at}: the block refers to entity (dimension {dim}, tag {tag}), which is not in $Entities"
    )]
    MissingEntity { at: Location, dim: i32, tag: i32 },
    #[error("{at}: entity dimension {dim} is not 0, 1, 2 or 3")]
    BadEntityDim { at: Location, dim: i32 },
    #[error("{at}: unknown element type {element_type}")]
    UnknownElementType { at: Location, element_type: i32 },
    #[error("{at}: element type {element_type} has dimension {type_dim} but its block's entity has dimension {entity_dim}")]
    ElementDimMismatch {
        at: Location,
        element_type: i32,
        type_dim: usize,
        entity_dim: i32,
    },
    #[error("$Elements: element type {element_type} ({name}) is not supported in a {dim}D mesh: only first-order simplices are read, 3-node triangles with 2-node lines (2D) or 4-node tetrahedra with 3-node triangles (3D). {hint}")]
    UnsupportedElementType {
        element_type: i32,
        name: &'static str,
        dim: usize,
        hint: &'static str,
    },
    #[error("{at}: element {element} has {count} tags; at most 4096 are read")]
    TooManyTags {
        at: Location,
        element: u64,
        count: i64,
    },
    #[error("$Nodes: node {node} has z = {z}, but the mesh has triangle cells, so it must be 2D (all z = 0)")]
    NotPlanar { node: u64, z: f64 },
    #[error("$Elements: the mesh has no triangles or tetrahedra")]
    NoCells,
    #[error("the file has no {0} section")]
    MissingSection(&'static str),
    #[error("the file has two {0} sections")]
    DuplicateSection(&'static str),
    #[error("{0} must come before {1}")]
    SectionOrder(&'static str, &'static str),
    #[error("{at}: physical group (dimension {dim}, tag {tag}) is named twice")]
    DuplicatePhysicalName { at: Location, dim: usize, tag: i32 },
    #[error("{at}: section {name:?} has no matching $End line")]
    UnterminatedSection { at: Location, name: String },
}

/// Reads an MSH 4.1 or 2.2 file from its bytes.
pub fn read(data: &[u8]) -> Result<MshMesh, MshError> {
    Reader::new(data).read()
}

/// Element types this reader can size: (gmsh type, nodes, dimension, name).
const ELEMENT_TYPES: [(i32, usize, usize, &str); 31] = [
    (1, 2, 1, "2-node line"),
    (2, 3, 2, "3-node triangle"),
    (3, 4, 2, "4-node quadrangle"),
    (4, 4, 3, "4-node tetrahedron"),
    (5, 8, 3, "8-node hexahedron"),
    (6, 6, 3, "6-node prism"),
    (7, 5, 3, "5-node pyramid"),
    (8, 3, 1, "3-node second-order line"),
    (9, 6, 2, "6-node second-order triangle"),
    (10, 9, 2, "9-node second-order quadrangle"),
    (11, 10, 3, "10-node second-order tetrahedron"),
    (12, 27, 3, "27-node second-order hexahedron"),
    (13, 18, 3, "18-node second-order prism"),
    (14, 14, 3, "14-node second-order pyramid"),
    (15, 1, 0, "point"),
    (16, 8, 2, "8-node second-order quadrangle"),
    (17, 20, 3, "20-node second-order hexahedron"),
    (18, 15, 3, "15-node second-order prism"),
    (19, 13, 3, "13-node second-order pyramid"),
    (20, 9, 2, "9-node third-order triangle"),
    (21, 10, 2, "10-node third-order triangle"),
    (22, 12, 2, "12-node fourth-order triangle"),
    (23, 15, 2, "15-node fourth-order triangle"),
    (24, 15, 2, "15-node fifth-order triangle"),
    (25, 21, 2, "21-node fifth-order triangle"),
    (26, 4, 1, "4-node third-order line"),
    (27, 5, 1, "5-node fourth-order line"),
    (28, 6, 1, "6-node fifth-order line"),
    (29, 20, 3, "20-node third-order tetrahedron"),
    (30, 35, 3, "35-node fourth-order tetrahedron"),
    (31, 56, 3, "56-node fifth-order tetrahedron"),
];

/// How to export a mesh without the element type `t` (not a first-order simplex).
fn export_hint(t: i32) -> &'static str {
    match t {
        3 | 5..=7 | 10 | 12..=14 | 16..=19 => {
            "Mesh with triangles (2D) or tetrahedra (gmsh -3) without recombination (Mesh.RecombineAll = 0, no Recombine or Transfinite volumes), first order (gmsh -order 1)."
        }
        _ => "Export first-order elements: gmsh -order 1 (or Mesh.ElementOrder = 1), with -2 for triangles or -3 for tetrahedra.",
    }
}

/// The element type `t`: (nodes, dimension, name).
fn type_info(t: i32) -> Option<(usize, usize, &'static str)> {
    ELEMENT_TYPES
        .iter()
        .find(|e| e.0 == t)
        .map(|&(_, n, d, name)| (n, d, name))
}

/// The slot of [`Kept`] that keeps elements of type `t` (lines, triangles, tetrahedra), or
/// None for points and refused types (noted in `unsupported`).
fn slot(
    t: i32,
    type_dim: usize,
    name: &'static str,
    unsupported: &mut Vec<(i32, usize, &'static str)>,
) -> Option<usize> {
    match t {
        1 => Some(0),
        2 => Some(1),
        4 => Some(2),
        15 => None,
        _ => {
            if !unsupported.iter().any(|u| u.0 == t) {
                unsupported.push((t, type_dim, name));
            }
            None
        }
    }
}

/// An error if a refused type is of the cell or facet dimension (or higher), naming the
/// refused type of the highest dimension.
fn check_types(
    kept: &[Kept; 3],
    unsupported: &[(i32, usize, &'static str)],
) -> Result<(), MshError> {
    let dim = if !kept[2].nodes.is_empty() { 3 } else { 2 };
    // The cells' type first: a second-order mesh's lines are second-order too.
    if let Some(&(element_type, _, name)) = unsupported
        .iter()
        .rev()
        .filter(|u| u.1 == dim || u.1 + 1 == dim || u.1 > dim)
        .max_by_key(|u| u.1)
    {
        return Err(MshError::UnsupportedElementType {
            element_type,
            name,
            dim,
            hint: export_hint(element_type),
        });
    }
    Ok(())
}

/// The file format version.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Version {
    V41,
    V22,
}

#[derive(Clone, Copy)]
struct Binary {
    big_endian: bool,
    size_t: usize,
}

/// The elements of one type that the mesh may keep, flat, with each element's entity tag
/// (in 2.2, its physical tag).
#[derive(Default)]
struct Kept {
    nodes: Vec<usize>,
    entities: Vec<i32>,
}

impl Kept {
    /// Drops every element (of `per` nodes) that repeats the element before it.
    fn dedup_consecutive(&mut self, per: usize) {
        let n = self.entities.len();
        let mut kept = 0;
        for e in 0..n {
            if kept > 0
                && self.nodes[per * e..per * (e + 1)] == self.nodes[per * (kept - 1)..per * kept]
            {
                continue;
            }
            self.nodes.copy_within(per * e..per * (e + 1), per * kept);
            self.entities[kept] = self.entities[e];
            kept += 1;
        }
        self.nodes.truncate(per * kept);
        self.entities.truncate(kept);
    }
}

/// The `$Nodes` section: coordinates and tags in file order, and each tag's index.
struct Nodes {
    coords: Vec<[f64; 3]>,
    tags: Vec<u64>,
    index: HashMap<u64, usize>,
}

struct Reader<'a> {
    data: &'a [u8],
    pos: usize,
    section: &'static str,
    binary: Option<Binary>,
    version: Version,
}

impl<'a> Reader<'a> {
    fn new(data: &'a [u8]) -> Self {
        Reader {
            data,
            pos: 0,
            section: "$MeshFormat",
            binary: None,
            version: Version::V41,
        }
    }

    fn at(&self) -> Location {
        self.loc(self.pos)
    }

    /// The offset of the next item (past whitespace in ASCII); made a [`Location`] only on
    /// error, since counting lines on every item would be quadratic.
    fn mark(&mut self) -> usize {
        if self.binary.is_none() {
            self.skip_ws();
        }
        self.pos
    }

    fn loc(&self, pos: usize) -> Location {
        let offset = pos.min(self.data.len());
        Location {
            section: self.section,
            line: 1 + self.data[..offset].iter().filter(|&&b| b == b'\n').count(),
            offset,
        }
    }

    fn remaining(&self) -> usize {
        self.data.len().saturating_sub(self.pos)
    }

    fn skip_ws(&mut self) {
        while self.pos < self.data.len() && self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
    }

    /// The next whitespace-separated token.
    fn token(&mut self, expected: &'static str) -> Result<&'a [u8], MshError> {
        self.skip_ws();
        if self.pos >= self.data.len() {
            return Err(MshError::Truncated {
                at: self.at(),
                expected,
            });
        }
        let start = self.pos;
        while self.pos < self.data.len() && !self.data[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        Ok(&self.data[start..self.pos])
    }

    fn syntax(&self, start: usize, expected: &'static str, found: &[u8]) -> MshError {
        let shown = &found[..found.len().min(40)];
        MshError::Syntax {
            at: self.loc(start),
            expected,
            found: String::from_utf8_lossy(shown).into_owned(),
        }
    }

    fn ascii<T: std::str::FromStr>(&mut self, expected: &'static str) -> Result<T, MshError> {
        self.skip_ws();
        let start = self.pos;
        let tok = self.token(expected)?;
        std::str::from_utf8(tok)
            .ok()
            .and_then(|s| s.parse().ok())
            .ok_or_else(|| self.syntax(start, expected, tok))
    }

    fn bytes<const N: usize>(&mut self, expected: &'static str) -> Result<[u8; N], MshError> {
        let Some(slice) = self.data.get(self.pos..self.pos.saturating_add(N)) else {
            return Err(MshError::Truncated {
                at: self.at(),
                expected,
            });
        };
        let mut out = [0; N];
        out.copy_from_slice(slice);
        if self.binary.is_some_and(|b| b.big_endian) {
            out.reverse();
        }
        self.pos += N;
        Ok(out)
    }

    /// A C `int` (4 bytes in binary).
    fn int(&mut self, expected: &'static str) -> Result<i32, MshError> {
        match self.binary {
            None => self.ascii(expected),
            Some(_) => Ok(i32::from_le_bytes(self.bytes::<4>(expected)?)),
        }
    }

    /// A C `size_t` (4 or 8 bytes in binary).
    /// A node or element tag (`expected` names it in errors) and where it starts: a size
    /// that must not be 0.
    fn tag(
        &mut self,
        expected: &'static str,
        what: &'static str,
    ) -> Result<(u64, usize), MshError> {
        let at = self.mark();
        let tag = self.number(expected)?;
        if tag == 0 {
            return Err(MshError::ZeroTag {
                at: self.loc(at),
                what,
            });
        }
        Ok((tag, at))
    }

    /// A node or element number: a `size_t` in 4.1, an `int` in 2.2 (not negative).
    fn number(&mut self, expected: &'static str) -> Result<u64, MshError> {
        if self.version == Version::V41 || self.binary.is_none() {
            return self.size(expected);
        }
        let at = self.pos;
        let n = self.int(expected)?;
        u64::try_from(n).map_err(|_| self.syntax(at, expected, n.to_string().as_bytes()))
    }

    fn size(&mut self, expected: &'static str) -> Result<u64, MshError> {
        match self.binary {
            None => self.ascii(expected),
            Some(Binary { size_t: 4, .. }) => {
                Ok(u32::from_le_bytes(self.bytes::<4>(expected)?) as u64)
            }
            Some(_) => Ok(u64::from_le_bytes(self.bytes::<8>(expected)?)),
        }
    }

    fn double(&mut self, expected: &'static str) -> Result<f64, MshError> {
        match self.binary {
            None => self.ascii(expected),
            Some(_) => Ok(f64::from_le_bytes(self.bytes::<8>(expected)?)),
        }
    }

    /// The minimum bytes of `ints` ints, `sizes` size_ts and `doubles` doubles.
    fn min_bytes(&self, ints: usize, sizes: usize, doubles: usize) -> usize {
        match self.binary {
            // A token is at least one character and one separator.
            None => 2 * (ints + sizes + doubles),
            Some(b) => 4 * ints + b.size_t * sizes + 8 * doubles,
        }
    }

    /// A count of items of at least `item_bytes` each, bounded by the bytes left.
    fn count(&mut self, what: &'static str, item_bytes: usize) -> Result<usize, MshError> {
        let at = self.mark();
        let count = self.size(what)?;
        let remaining = self.remaining();
        let fits = usize::try_from(count)
            .ok()
            .and_then(|c| c.checked_mul(item_bytes.max(1)))
            .is_some_and(|b| b <= remaining);
        if !fits {
            return Err(MshError::HugeCount {
                at: self.loc(at),
                what,
                count,
                remaining,
            });
        }
        Ok(count as usize)
    }

    /// The `$End…` line closing the current section.
    fn end(&mut self, end: &'static str) -> Result<(), MshError> {
        self.skip_ws();
        let start = self.pos;
        let tok = self.token(end)?;
        if tok != end.as_bytes() {
            return Err(self.syntax(start, end, tok));
        }
        Ok(())
    }

    fn read(mut self) -> Result<MshMesh, MshError> {
        self.skip_ws();
        if self.token("$MeshFormat").ok() != Some(b"$MeshFormat".as_slice()) {
            return Err(MshError::NotMsh);
        }
        self.mesh_format()?;
        let mut names: Option<Vec<PhysicalName>> = None;
        let mut entities: Option<HashMap<(i32, i32), Vec<i32>>> = None;
        let mut nodes: Option<Nodes> = None;
        let mut elements: Option<[Kept; 3]> = None;
        loop {
            self.skip_ws();
            if self.pos >= self.data.len() {
                break;
            }
            self.section = "the file";
            let start = self.pos;
            let tok = self.token("a section")?;
            // Binary data starts right after the section line.
            if self.data[self.pos..].starts_with(b"\r\n") {
                self.pos += 2;
            } else if self.pos < self.data.len() {
                self.pos += 1;
            }
            match tok {
                b"$MeshFormat" => return Err(MshError::DuplicateSection("$MeshFormat")),
                b"$PhysicalNames" => set_once(&mut names, "$PhysicalNames", || {
                    self.section = "$PhysicalNames";
                    self.physical_names()
                })?,
                b"$Entities" if self.version == Version::V41 => {
                    set_once(&mut entities, "$Entities", || {
                        self.section = "$Entities";
                        self.entities()
                    })?
                }
                b"$Nodes" => set_once(&mut nodes, "$Nodes", || {
                    self.section = "$Nodes";
                    match self.version {
                        Version::V41 => self.nodes(),
                        Version::V22 => self.nodes_v2(),
                    }
                })?,
                b"$Elements" if self.version == Version::V22 => {
                    let Some(Nodes { index, .. }) = &nodes else {
                        return Err(MshError::SectionOrder("$Nodes", "$Elements"));
                    };
                    if elements.is_some() {
                        return Err(MshError::DuplicateSection("$Elements"));
                    }
                    self.section = "$Elements";
                    let (kept, physicals) = self.elements_v2(index)?;
                    elements = Some(kept);
                    entities = Some(physicals);
                }
                b"$Elements" => {
                    let Some(ents) = &entities else {
                        return Err(MshError::SectionOrder("$Entities", "$Elements"));
                    };
                    let Some(Nodes { index, .. }) = &nodes else {
                        return Err(MshError::SectionOrder("$Nodes", "$Elements"));
                    };
                    set_once(&mut elements, "$Elements", || {
                        self.section = "$Elements";
                        self.elements(ents, index)
                    })?
                }
                _ if tok.first() == Some(&b'$') && !tok.starts_with(b"$End") => {
                    self.skip_section(tok)?
                }
                _ => return Err(self.syntax(start, "a section such as $Nodes", tok)),
            }
        }
        let names = names.unwrap_or_default();
        let entities = entities.ok_or(MshError::MissingSection(match self.version {
            Version::V41 => "$Entities",
            Version::V22 => "$Elements",
        }))?;
        let Nodes {
            coords: nodes,
            tags: node_tags,
            ..
        } = nodes.ok_or(MshError::MissingSection("$Nodes"))?;
        let [lines, mut triangles, mut tetrahedra] =
            elements.ok_or(MshError::MissingSection("$Elements"))?;
        if self.version == Version::V22 {
            // 2.2 repeats an element once per physical group it is in; a cell is one cell.
            if tetrahedra.nodes.is_empty() {
                triangles.dedup_consecutive(3);
            } else {
                tetrahedra.dedup_consecutive(4);
            }
        }
        let (dim, cells, facets) = if !tetrahedra.nodes.is_empty() {
            (3, tetrahedra, triangles)
        } else if !triangles.nodes.is_empty() {
            if let Some((i, p)) = nodes.iter().enumerate().find(|(_, p)| p[2] != 0.0) {
                return Err(MshError::NotPlanar {
                    node: node_tags[i],
                    z: p[2],
                });
            }
            (2, triangles, lines)
        } else {
            return Err(MshError::NoCells);
        };
        let mut by_tag: BTreeMap<i32, Vec<usize>> = BTreeMap::new();
        for (facet, &entity) in facets.nodes.chunks_exact(dim).zip(&facets.entities) {
            // Elements were checked against $Entities when read.
            for &tag in entities
                .get(&(dim as i32 - 1, entity))
                .into_iter()
                .flatten()
            {
                by_tag.entry(tag).or_default().extend_from_slice(facet);
            }
        }
        let groups = by_tag
            .into_iter()
            .map(|(tag, facet_nodes)| FacetGroup {
                tag,
                name: names
                    .iter()
                    .find(|n| n.dim == dim - 1 && n.tag == tag)
                    .map(|n| n.name.clone()),
                facet_nodes,
                facet_len: dim,
            })
            .collect();
        Ok(MshMesh {
            dim,
            nodes,
            node_tags,
            cell_nodes: cells.nodes,
            groups,
            physical_names: names,
        })
    }

    fn mesh_format(&mut self) -> Result<(), MshError> {
        let start = self.pos;
        let version = self.token("the version")?;
        if version == b"2.2" {
            self.version = Version::V22;
        } else if version != b"4.1" {
            let shown = &version[..version.len().min(20)];
            let v = String::from_utf8_lossy(shown).into_owned();
            if v.parse::<f64>().is_ok() {
                return Err(MshError::UnsupportedVersion(v));
            }
            return Err(self.syntax(start, "a version number", version));
        }
        let file_type: u32 = self.ascii("the file type (0 or 1)")?;
        let data_size: usize = self.ascii("the data size")?;
        if data_size != 4 && data_size != 8 {
            return Err(MshError::BadHeader {
                at: self.at(),
                what: "the data size (the width of size_t) must be 4 or 8",
            });
        }
        match file_type {
            0 => {}
            1 => {
                // The integer 1 follows the line, in the writer's byte order.
                if self.data.get(self.pos) == Some(&b'\n') {
                    self.pos += 1;
                } else if self.data.get(self.pos..self.pos + 2) == Some(b"\r\n") {
                    self.pos += 2;
                }
                let at = self.mark();
                let one: [u8; 4] = self.bytes("the byte-order integer 1")?;
                let big_endian = match (u32::from_le_bytes(one), u32::from_be_bytes(one)) {
                    (1, _) => false,
                    (_, 1) => true,
                    _ => {
                        return Err(MshError::BadHeader {
                            at: self.loc(at),
                            what: "the binary integer 1 that fixes the byte order is missing",
                        });
                    }
                };
                self.binary = Some(Binary {
                    big_endian,
                    size_t: data_size,
                });
            }
            _ => {
                return Err(MshError::BadHeader {
                    at: self.at(),
                    what: "the file type must be 0 (ASCII) or 1 (binary)",
                });
            }
        }
        self.end("$EndMeshFormat")
    }

    fn physical_names(&mut self) -> Result<Vec<PhysicalName>, MshError> {
        let binary = self.binary.take();
        let result = self.physical_names_ascii();
        self.binary = binary;
        result
    }

    fn physical_names_ascii(&mut self) -> Result<Vec<PhysicalName>, MshError> {
        let at = self.mark();
        // dimension, tag, and a quoted name: at least 8 bytes.
        let count = self.count("the number of physical names", 8)?;
        if count > MAX_PHYSICAL_GROUPS {
            return Err(MshError::TooMany {
                at: self.loc(at),
                what: "physical names",
                count: count as u64,
                limit: MAX_PHYSICAL_GROUPS,
            });
        }
        let mut names: Vec<PhysicalName> = Vec::with_capacity(count);
        for _ in 0..count {
            let at = self.mark();
            let dim: usize = self.ascii("the dimension of a physical name")?;
            if dim > 3 {
                return Err(MshError::BadEntityDim {
                    at: self.loc(at),
                    dim: dim as i32,
                });
            }
            let tag: i32 = self.ascii("the tag of a physical name")?;
            self.skip_ws();
            let start = self.pos;
            let rest = &self.data[start..];
            let line_end = rest.iter().position(|&b| b == b'\n').unwrap_or(rest.len());
            let line = &rest[..line_end];
            let name = line
                .strip_prefix(b"\"")
                .and_then(|l| l.iter().position(|&b| b == b'"').map(|e| &l[..e]))
                .and_then(|n| std::str::from_utf8(n).ok())
                .ok_or_else(|| self.syntax(start, "a name in double quotes", line))?;
            self.pos = start + line_end;
            if names.iter().any(|n| n.dim == dim && n.tag == tag) {
                return Err(MshError::DuplicatePhysicalName {
                    at: self.loc(at),
                    dim,
                    tag,
                });
            }
            names.push(PhysicalName {
                dim,
                tag,
                name: name.to_string(),
            });
        }
        self.end("$EndPhysicalNames")?;
        Ok(names)
    }

    /// The physical tags of each entity, by (dimension, tag).
    fn entities(&mut self) -> Result<HashMap<(i32, i32), Vec<i32>>, MshError> {
        let mut counts = [0usize; 4];
        for c in &mut counts {
            // A point has 1 int, 3 doubles and 1 size_t at least.
            let item = self.min_bytes(1, 1, 3);
            *c = self.count("the number of entities", item)?;
        }
        let mut out: HashMap<(i32, i32), Vec<i32>> = HashMap::new();
        let mut groups: HashSet<(i32, i32)> = HashSet::new();
        for (dim, &count) in counts.iter().enumerate() {
            for _ in 0..count {
                let at = self.mark();
                let tag = self.int("an entity tag")?;
                let boxes = if dim == 0 { 3 } else { 6 };
                for _ in 0..boxes {
                    self.double("an entity's coordinate")?;
                }
                let item = self.min_bytes(1, 0, 0);
                let n = self.count("the number of physical tags", item)?;
                let mut tags = Vec::with_capacity(n);
                for _ in 0..n {
                    let t = self.int("a physical tag")?;
                    groups.insert((dim as i32, t));
                    tags.push(t);
                }
                if groups.len() > MAX_PHYSICAL_GROUPS {
                    return Err(MshError::TooMany {
                        at: self.loc(at),
                        what: "physical groups",
                        count: groups.len() as u64,
                        limit: MAX_PHYSICAL_GROUPS,
                    });
                }
                if dim > 0 {
                    let n = self.count("the number of bounding entities", item)?;
                    for _ in 0..n {
                        self.int("a bounding entity tag")?;
                    }
                }
                out.insert((dim as i32, tag), tags);
            }
        }
        self.end("$EndEntities")?;
        Ok(out)
    }

    fn nodes(&mut self) -> Result<Nodes, MshError> {
        let block_bytes = self.min_bytes(3, 1, 0);
        let node_bytes = self.min_bytes(0, 1, 3);
        let blocks = self.count("the number of node blocks", block_bytes)?;
        let declared = self.count("the number of nodes", node_bytes)?;
        self.size("the minimum node tag")?;
        self.size("the maximum node tag")?;
        let mut coords = Vec::with_capacity(declared);
        let mut tags = Vec::with_capacity(declared);
        let mut index = HashMap::with_capacity(declared);
        for _ in 0..blocks {
            let at = self.mark();
            let dim = self.int("the entity dimension of a node block")?;
            if !(0..=3).contains(&dim) {
                return Err(MshError::BadEntityDim {
                    at: self.loc(at),
                    dim,
                });
            }
            self.int("the entity tag of a node block")?;
            let parametric = self.int("the parametric flag")?;
            let extra = if parametric != 0 { dim as usize } else { 0 };
            let n = self.count(
                "the number of nodes in the block",
                self.min_bytes(0, 1, 3 + extra),
            )?;
            let first = tags.len();
            for _ in 0..n {
                let (tag, at) = self.tag("a node tag", "a node")?;
                if index.insert(tag, tags.len()).is_some() {
                    return Err(MshError::DuplicateNode {
                        at: self.loc(at),
                        node: tag,
                    });
                }
                tags.push(tag);
            }
            for &tag in &tags[first..] {
                let at = self.mark();
                let mut p = [0.0; 3];
                for c in &mut p {
                    *c = self.double("a node coordinate")?;
                }
                for _ in 0..extra {
                    self.double("a parametric coordinate")?;
                }
                if p.iter().any(|c| !c.is_finite()) {
                    return Err(MshError::NonFinite {
                        at: self.loc(at),
                        node: tag,
                    });
                }
                coords.push(p);
            }
        }
        if tags.len() as u64 != declared as u64 {
            return Err(MshError::BadCount {
                section: "$Nodes",
                what: "nodes",
                declared: declared as u64,
                found: tags.len() as u64,
            });
        }
        self.end("$EndNodes")?;
        Ok(Nodes {
            coords,
            tags,
            index,
        })
    }

    /// Lines, triangles and tetrahedra, with node tags mapped to indices.
    fn elements(
        &mut self,
        entities: &HashMap<(i32, i32), Vec<i32>>,
        index: &HashMap<u64, usize>,
    ) -> Result<[Kept; 3], MshError> {
        let block_bytes = self.min_bytes(3, 1, 0);
        let blocks = self.count("the number of element blocks", block_bytes)?;
        let declared = self.count("the number of elements", self.min_bytes(0, 2, 0))?;
        self.size("the minimum element tag")?;
        self.size("the maximum element tag")?;
        let mut kept: [Kept; 3] = Default::default();
        let mut unsupported: Vec<(i32, usize, &'static str)> = Vec::new();
        let mut total = 0u64;
        for _ in 0..blocks {
            let at = self.mark();
            let entity_dim = self.int("the entity dimension of an element block")?;
            if !(0..=3).contains(&entity_dim) {
                return Err(MshError::BadEntityDim {
                    at: self.loc(at),
                    dim: entity_dim,
                });
            }
            let entity = self.int("the entity tag of an element block")?;
            if !entities.contains_key(&(entity_dim, entity)) {
                return Err(MshError::MissingEntity {
                    at: self.loc(at),
                    dim: entity_dim,
                    tag: entity,
                });
            }
            let element_type = self.int("the element type")?;
            let Some((per, type_dim, name)) = type_info(element_type) else {
                return Err(MshError::UnknownElementType {
                    at: self.loc(at),
                    element_type,
                });
            };
            if type_dim as i32 != entity_dim {
                return Err(MshError::ElementDimMismatch {
                    at: self.loc(at),
                    element_type,
                    type_dim,
                    entity_dim,
                });
            }
            let n = self.count(
                "the number of elements in the block",
                self.min_bytes(0, 1 + per, 0),
            )?;
            total += n as u64;
            let slot = slot(element_type, type_dim, name, &mut unsupported);
            if let Some(s) = slot {
                kept[s].nodes.reserve(n * per);
                kept[s].entities.reserve(n);
            }
            for _ in 0..n {
                let (tag, _) = self.tag("an element tag", "an element")?;
                for _ in 0..per {
                    let node = self.size("a node tag of an element")?;
                    let Some(&i) = index.get(&node) else {
                        return Err(MshError::MissingNode { element: tag, node });
                    };
                    if let Some(s) = slot {
                        kept[s].nodes.push(i);
                    }
                }
                if let Some(s) = slot {
                    kept[s].entities.push(entity);
                }
            }
        }
        if total != declared as u64 {
            return Err(MshError::BadCount {
                section: "$Elements",
                what: "elements",
                declared: declared as u64,
                found: total,
            });
        }
        self.end("$EndElements")?;
        check_types(&kept, &unsupported)?;
        Ok(kept)
    }

    /// Skips an unknown section up to its `$End` line.
    fn skip_section(&mut self, tok: &[u8]) -> Result<(), MshError> {
        let name = &tok[1..];
        let mut end = b"\n$End".to_vec();
        end.extend_from_slice(name);
        let at = self.mark();
        let rest = &self.data[self.pos..];
        match rest.windows(end.len()).position(|w| w == end.as_slice()) {
            Some(i) => {
                self.pos += i + end.len();
                Ok(())
            }
            None => Err(MshError::UnterminatedSection {
                at: self.loc(at),
                name: String::from_utf8_lossy(&tok[..tok.len().min(40)]).into_owned(),
            }),
        }
    }
}

/// Reads a section into its slot, refusing a second copy of the section.
fn set_once<T>(
    slot: &mut Option<T>,
    section: &'static str,
    read: impl FnOnce() -> Result<T, MshError>,
) -> Result<(), MshError> {
    if slot.is_some() {
        return Err(MshError::DuplicateSection(section));
    }
    *slot = Some(read()?);
    Ok(())
}
