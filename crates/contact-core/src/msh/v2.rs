//! The sections of gmsh MSH 2.2 that differ from 4.1 (gmsh reference manual, "MSH file
//! format version 2 (Legacy)"): `$MeshFormat` and `$PhysicalNames` are read as in 4.1, there
//! is no `$Entities`, and
//! - `$Nodes`: the number of nodes (ASCII), then per node its number and x, y, z (binary: an
//!   `int` and three doubles);
//! - `$Elements`: the number of elements (ASCII), then per element its number, type, number of
//!   tags, the tags (the first is the physical group, 0 for none; the others — elementary
//!   entity, partitions — are read past) and its nodes. Binary files write the elements in
//!   blocks of one type and one number of tags: a header of three `int`s (type, elements in
//!   the block, tags), then per element `int`s: number, tags, nodes.
//!
//! An element in several physical groups is written once per group; the physical tag takes
//! the place of 4.1's entity tag, so each group gets its facets and [`super::Reader::read`]
//! keeps a repeated cell once.

use std::collections::HashMap;

use super::{check_types, slot, type_info, Kept, MshError, Nodes, Reader, MAX_PHYSICAL_GROUPS};

/// More tags than any writer puts on an element (gmsh writes 2, or 3 + partitions).
const MAX_TAGS: usize = 4096;

impl Reader<'_> {
    /// A count written in ASCII, also in a binary file, of items of at least `item_bytes`
    /// each (binary data starts after its line).
    fn ascii_count(&mut self, what: &'static str, item_bytes: usize) -> Result<usize, MshError> {
        let binary = self.binary.take();
        let count = self.count(what, item_bytes);
        self.binary = binary;
        let count = count?;
        if self.binary.is_some() {
            if self.data[self.pos..].starts_with(b"\r\n") {
                self.pos += 2;
            } else if self.pos < self.data.len() {
                self.pos += 1;
            }
        }
        Ok(count)
    }

    pub(super) fn nodes_v2(&mut self) -> Result<Nodes, MshError> {
        let node_bytes = self.min_bytes(1, 0, 3);
        let declared = self.ascii_count("the number of nodes", node_bytes)?;
        let mut coords = Vec::with_capacity(declared);
        let mut tags = Vec::with_capacity(declared);
        let mut index = HashMap::with_capacity(declared);
        for _ in 0..declared {
            let (tag, at) = self.tag("a node number", "a node")?;
            if index.insert(tag, tags.len()).is_some() {
                return Err(MshError::DuplicateNode {
                    at: self.loc(at),
                    node: tag,
                });
            }
            let mut p = [0.0; 3];
            for c in &mut p {
                *c = self.double("a node coordinate")?;
            }
            if p.iter().any(|c| !c.is_finite()) {
                return Err(MshError::NonFinite {
                    at: self.loc(at),
                    node: tag,
                });
            }
            tags.push(tag);
            coords.push(p);
        }
        self.end("$EndNodes")?;
        Ok(Nodes {
            coords,
            tags,
            index,
        })
    }

    /// Lines, triangles and tetrahedra with node numbers mapped to indices, each with its
    /// physical tag in place of an entity tag; and the map from (dimension, physical tag) to
    /// the physical tags ([`Reader::entities`]'s shape: empty for tag 0).
    #[allow(clippy::type_complexity)]
    pub(super) fn elements_v2(
        &mut self,
        index: &HashMap<u64, usize>,
    ) -> Result<([Kept; 3], HashMap<(i32, i32), Vec<i32>>), MshError> {
        // Number, type and tag count, and at least one node.
        let element_bytes = self.min_bytes(4, 0, 0);
        let declared = self.ascii_count("the number of elements", element_bytes)?;
        let mut kept: [Kept; 3] = Default::default();
        let mut physicals: HashMap<(i32, i32), Vec<i32>> = HashMap::new();
        let mut unsupported = Vec::new();
        let mut tags = Vec::new();
        let mut read = 0usize;
        while read < declared {
            // ASCII: one element per "block"; binary: a header with the block's size.
            let at = self.mark();
            let (element_type, in_block, n_tags) = if self.binary.is_some() {
                let t = self.int("the element type of a block")?;
                let n = self.int("the number of elements in the block")?;
                let k = self.int("the number of tags")?;
                let n = usize::try_from(n)
                    .ok()
                    .filter(|&n| n <= declared - read)
                    .ok_or(MshError::BadCount {
                        section: "$Elements",
                        what: "elements",
                        declared: declared as u64,
                        found: read as u64 + n.max(0) as u64,
                    })?;
                (t, n, k as i64)
            } else {
                (0, 1, 0)
            };
            for _ in 0..in_block {
                let (tag, tag_at) = self.tag("an element number", "an element")?;
                let (element_type, n_tags) = if self.binary.is_some() {
                    (element_type, n_tags)
                } else {
                    let t = self.int("the element type")?;
                    let k: i64 = self.ascii("the number of tags")?;
                    (t, k)
                };
                let Some((per, type_dim, name)) = type_info(element_type) else {
                    return Err(MshError::UnknownElementType {
                        at: self.loc(at.max(tag_at)),
                        element_type,
                    });
                };
                let n_tags = usize::try_from(n_tags)
                    .ok()
                    .filter(|&k| k <= MAX_TAGS)
                    .ok_or(MshError::TooManyTags {
                        at: self.loc(tag_at),
                        element: tag,
                        count: n_tags,
                    })?;
                tags.clear();
                for _ in 0..n_tags {
                    tags.push(self.int("an element tag")?);
                }
                let physical = tags.first().copied().unwrap_or(0);
                let slot = slot(element_type, type_dim, name, &mut unsupported);
                for _ in 0..per {
                    let node = self.number("a node number of an element")?;
                    let Some(&i) = index.get(&node) else {
                        return Err(MshError::MissingNode { element: tag, node });
                    };
                    if let Some(s) = slot {
                        kept[s].nodes.push(i);
                    }
                }
                if let Some(s) = slot {
                    kept[s].entities.push(physical);
                    physicals
                        .entry((type_dim as i32, physical))
                        .or_insert_with(|| {
                            if physical == 0 {
                                vec![]
                            } else {
                                vec![physical]
                            }
                        });
                    if physicals.len() > MAX_PHYSICAL_GROUPS {
                        return Err(MshError::TooMany {
                            at: self.loc(tag_at),
                            what: "physical groups",
                            count: physicals.len() as u64,
                            limit: MAX_PHYSICAL_GROUPS,
                        });
                    }
                }
                read += 1;
            }
        }
        self.end("$EndElements")?;
        check_types(&kept, &unsupported)?;
        Ok((kept, physicals))
    }
}
