//! Compact binary storage of stored steps ([`StepFields`]) and checkpoints ([`State`]).
//!
//! A run may store many steps of a large mesh, so results are kept as raw little-endian
//! binary (8 bytes per `f64`, bit-exact, a fraction of the size of JSON and no float
//! printing/parsing) and only rendered to JSON or VTK when asked for. Both formats are
//! self-describing and end with a checksum, so a truncated or corrupted file is reported as
//! an error and never decoded into plausible-looking garbage.
//!
//! # Step format (`CSSTEP`, version 1)
//!
//! All integers and floats are little-endian; `f64` values are stored as their IEEE-754 bits.
//!
//! | field | encoding |
//! | --- | --- |
//! | magic | the 6 bytes `CSSTEP` |
//! | version | `u16` (currently 1) |
//! | `n` | `u64` |
//! | `t` | `f64` |
//! | `u`, `w`, `zeta` | each: presence flag `u8` (0 absent, 1 present); if present `u64` count, then count × `f64` |
//! | `sigma` | flag `u8`: 0 absent; 1 (2D): `u64` triangle count, then per triangle `f64` σ_xx, σ_yy, σ_xy; 2 (3D): `u64` tetrahedron count, then per tetrahedron `f64` σ_xx, σ_yy, σ_zz, σ_xy, σ_yz, σ_xz |
//! | `von_mises` | presence flag; if present `u64` count, then count × `f64` |
//! | `contact` | flag `u8`: 0 absent; 1 (2D) or 2 (3D): `u64` count, then per node: `u64` node, `f64` slip velocity, `f64` friction traction, `f64` bound, `u8` slipping (0 or 1), and in 3D 6 × `f64`: the tangential velocity and the traction as Cartesian vectors |
//! | `estimate` | presence flag; if present `u64` count, then count × `f64` (the a posteriori cell indicators; steps written before it end after `contact`) |
//! | checksum | the first 8 bytes of the SHA-256 of every byte before it |
//!
//! # Checkpoint format (`CSSTAT`, version 1)
//!
//! magic `CSSTAT`, version `u16`, `step` `u64`, `u` (`u64` count + count × `f64`),
//! `zeta` (`u64` count + count × `f64`), checksum as above.
//!
//! # Decoding is defensive
//!
//! Decoders never panic and never trust a length: each declared element count is checked
//! against the bytes that remain before anything is allocated, so hostile input cannot make
//! them allocate more than the input's own size. Flags must be exactly 0 or 1, no bytes may
//! follow the checksum, and the checksum must match.

use crate::solve::stepper::{ContactNode, State, StepFields, Stress};
use sha2::{Digest, Sha256};

/// Magic bytes that open an encoded [`StepFields`].
pub const STEP_MAGIC: &[u8; 6] = b"CSSTEP";
/// Magic bytes that open an encoded [`State`] (checkpoint).
pub const STATE_MAGIC: &[u8; 6] = b"CSSTAT";
/// The format version written by [`encode_step`] and [`encode_state`], and the only one read.
pub const FORMAT_VERSION: u16 = 1;

const CHECKSUM_LEN: usize = 8;
/// Bytes of one contact-node record: node, three `f64`s and the slipping flag (2D); and 6
/// `f64`s more in 3D.
const CONTACT_RECORD_LEN: usize = 8 + 3 * 8 + 1;
const CONTACT_RECORD_LEN_3D: usize = CONTACT_RECORD_LEN + 6 * 8;

/// Why bytes could not be decoded.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DecodeError {
    #[error("bad magic: not a {expected} file")]
    BadMagic { expected: &'static str },
    #[error("unsupported format version {found} (this build reads version {supported})")]
    UnsupportedVersion { found: u16, supported: u16 },
    #[error("truncated: {what} needs {needed} bytes but only {available} remain")]
    Truncated {
        what: &'static str,
        needed: usize,
        available: usize,
    },
    #[error(
        "length overflow: {what} declares {declared} elements of {element_size} bytes \
         but only {available} bytes remain"
    )]
    LengthOverflow {
        what: &'static str,
        declared: u64,
        element_size: usize,
        available: usize,
    },
    #[error("invalid {what} flag {value} (expected 0 or 1, or 2 for a dimension flag)")]
    BadFlag { what: &'static str, value: u8 },
    #[error("{what} value {value} does not fit this platform's usize")]
    ValueOutOfRange { what: &'static str, value: u64 },
    #[error("{count} unexpected bytes before the checksum")]
    TrailingBytes { count: usize },
    #[error("checksum mismatch (stored {stored:016x}, computed {computed:016x}): data is corrupt")]
    ChecksumMismatch { stored: u64, computed: u64 },
}

/// Encodes one stored step (see the module docs for the format).
pub fn encode_step(f: &StepFields) -> Vec<u8> {
    let arrays = [&f.u, &f.w, &f.zeta, &f.von_mises, &f.estimate]
        .iter()
        .map(|a| a.as_ref().map_or(0, |v| 8 + 8 * v.len()))
        .sum::<usize>();
    let sigma = f.sigma.as_ref().map_or(0, |s| match s {
        Stress::Plane(s) => 8 + 24 * s.len(),
        Stress::Solid(s) => 8 + 48 * s.len(),
    });
    let solid_contact = f
        .contact
        .as_ref()
        .is_some_and(|c| c.iter().any(|n| n.tangential_velocity.is_some()));
    let record = if solid_contact {
        CONTACT_RECORD_LEN_3D
    } else {
        CONTACT_RECORD_LEN
    };
    let contact = f.contact.as_ref().map_or(0, |c| 8 + record * c.len());
    let mut w = Writer::with_capacity(6 + 2 + 16 + 7 + arrays + sigma + contact + CHECKSUM_LEN);
    w.bytes(STEP_MAGIC);
    w.u16(FORMAT_VERSION);
    w.u64(f.n as u64);
    w.f64(f.t);
    w.opt_f64s(f.u.as_deref());
    w.opt_f64s(f.w.as_deref());
    w.opt_f64s(f.zeta.as_deref());
    match &f.sigma {
        None => w.u8(0),
        Some(Stress::Plane(s)) => {
            w.u8(1);
            w.u64(s.len() as u64);
            for v in s.iter().flatten() {
                w.f64(*v);
            }
        }
        Some(Stress::Solid(s)) => {
            w.u8(2);
            w.u64(s.len() as u64);
            for v in s.iter().flatten() {
                w.f64(*v);
            }
        }
    }
    w.opt_f64s(f.von_mises.as_deref());
    match &f.contact {
        None => w.u8(0),
        Some(c) => {
            w.u8(if solid_contact { 2 } else { 1 });
            w.u64(c.len() as u64);
            for node in c {
                w.u64(node.node as u64);
                w.f64(node.slip_velocity);
                w.f64(node.friction_traction);
                w.f64(node.bound);
                w.u8(u8::from(node.slipping));
                if solid_contact {
                    let zero = [0.0; 3];
                    for v in node.tangential_velocity.unwrap_or(zero) {
                        w.f64(v);
                    }
                    for v in node.traction.unwrap_or(zero) {
                        w.f64(v);
                    }
                }
            }
        }
    }
    w.opt_f64s(f.estimate.as_deref());
    w.finish()
}

/// Decodes bytes written by [`encode_step`]; any malformed, truncated or corrupted input is
/// an error, never a panic.
pub fn decode_step(bytes: &[u8]) -> Result<StepFields, DecodeError> {
    let mut r = Reader::open(bytes, STEP_MAGIC, "CSSTEP")?;
    let n = r.usize("step index n")?;
    let t = r.f64("time t")?;
    let u = r.opt_f64s("u")?;
    let w = r.opt_f64s("w")?;
    let zeta = r.opt_f64s("zeta")?;
    let sigma = match r.kind("sigma presence")? {
        0 => None,
        1 => {
            let count = r.count("sigma", 24)?;
            let mut s = Vec::with_capacity(count);
            for _ in 0..count {
                s.push([r.f64("sigma")?, r.f64("sigma")?, r.f64("sigma")?]);
            }
            Some(Stress::Plane(s))
        }
        _ => {
            let count = r.count("sigma", 48)?;
            let mut s = Vec::with_capacity(count);
            for _ in 0..count {
                let mut v = [0.0; 6];
                for x in &mut v {
                    *x = r.f64("sigma")?;
                }
                s.push(v);
            }
            Some(Stress::Solid(s))
        }
    };
    let von_mises = r.opt_f64s("von_mises")?;
    let contact = match r.kind("contact presence")? {
        0 => None,
        kind => {
            let solid = kind == 2;
            let record = if solid {
                CONTACT_RECORD_LEN_3D
            } else {
                CONTACT_RECORD_LEN
            };
            let count = r.count("contact", record)?;
            let mut c = Vec::with_capacity(count);
            for _ in 0..count {
                let mut node = ContactNode {
                    node: r.usize("contact node")?,
                    slip_velocity: r.f64("contact slip velocity")?,
                    friction_traction: r.f64("contact friction traction")?,
                    bound: r.f64("contact bound")?,
                    slipping: r.flag("contact slipping")?,
                    tangential_velocity: None,
                    traction: None,
                };
                if solid {
                    let mut v = [0.0; 6];
                    for x in &mut v {
                        *x = r.f64("contact vectors")?;
                    }
                    node.tangential_velocity = Some([v[0], v[1], v[2]]);
                    node.traction = Some([v[3], v[4], v[5]]);
                }
                c.push(node);
            }
            Some(c)
        }
    };
    let estimate = if r.available() > 0 {
        r.opt_f64s("estimate")?
    } else {
        None
    };
    r.close()?;
    Ok(StepFields {
        n,
        t,
        u,
        w,
        zeta,
        sigma,
        von_mises,
        contact,
        estimate,
    })
}

/// Encodes a checkpoint (see the module docs for the format); [`decode_state`] gives back a
/// bit-identical [`State`].
pub fn encode_state(s: &State) -> Vec<u8> {
    let mut w =
        Writer::with_capacity(6 + 2 + 8 + 16 + 8 * (s.u.len() + s.zeta.len()) + CHECKSUM_LEN);
    w.bytes(STATE_MAGIC);
    w.u16(FORMAT_VERSION);
    w.u64(s.step as u64);
    w.f64s(&s.u);
    w.f64s(&s.zeta);
    // The solvers' warm starts; checkpoints written before they were added end after ζ.
    w.f64s(&s.contact_velocity);
    let active: Vec<f64> = s.damage_active.iter().map(|&c| f64::from(c)).collect();
    w.f64s(&active);
    // ζ_{n−1}, from which the damage step's start is extrapolated; older checkpoints end
    // before it.
    w.f64s(&s.damage_before);
    // w_n when the run estimates its error; older checkpoints end before it.
    w.f64s(&s.w);
    w.finish()
}

/// Decodes bytes written by [`encode_state`]; any malformed, truncated or corrupted input is
/// an error, never a panic.
pub fn decode_state(bytes: &[u8]) -> Result<State, DecodeError> {
    let mut r = Reader::open(bytes, STATE_MAGIC, "CSSTAT")?;
    let step = r.usize("step")?;
    let u = r.f64s("u")?;
    let zeta = r.f64s("zeta")?;
    let (mut contact_velocity, mut damage_active) = (Vec::new(), Vec::new());
    if r.available() > 0 {
        contact_velocity = r.f64s("contact velocity")?;
        damage_active = r
            .f64s("damage active set")?
            .into_iter()
            .map(|c| match c {
                0.0 => Ok(0),
                1.0 => Ok(1),
                2.0 => Ok(2),
                _ => Err(DecodeError::ValueOutOfRange {
                    what: "damage active set",
                    value: c.to_bits(),
                }),
            })
            .collect::<Result<_, _>>()?;
    }
    let damage_before = if r.available() > 0 {
        r.f64s("damage before")?
    } else {
        Vec::new()
    };
    let w = if r.available() > 0 {
        r.f64s("w")?
    } else {
        Vec::new()
    };
    r.close()?;
    Ok(State {
        step,
        u,
        zeta,
        contact_velocity,
        damage_active,
        damage_before,
        w,
    })
}

/// The first 8 bytes of SHA-256, as a little-endian `u64`.
fn checksum(data: &[u8]) -> u64 {
    let digest = Sha256::digest(data);
    let mut first = [0u8; CHECKSUM_LEN];
    first.copy_from_slice(&digest[..CHECKSUM_LEN]);
    u64::from_le_bytes(first)
}

struct Writer {
    buf: Vec<u8>,
}

impl Writer {
    fn with_capacity(capacity: usize) -> Self {
        Writer {
            buf: Vec::with_capacity(capacity),
        }
    }

    fn bytes(&mut self, b: &[u8]) {
        self.buf.extend_from_slice(b);
    }

    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }

    fn u64(&mut self, v: u64) {
        self.bytes(&v.to_le_bytes());
    }

    fn f64(&mut self, v: f64) {
        self.bytes(&v.to_bits().to_le_bytes());
    }

    fn f64s(&mut self, values: &[f64]) {
        self.u64(values.len() as u64);
        for v in values {
            self.f64(*v);
        }
    }

    fn opt_f64s(&mut self, values: Option<&[f64]>) {
        match values {
            None => self.u8(0),
            Some(v) => {
                self.u8(1);
                self.f64s(v);
            }
        }
    }

    fn finish(mut self) -> Vec<u8> {
        let sum = checksum(&self.buf);
        self.u64(sum);
        self.buf
    }
}

/// Bounds-checked cursor over the bytes before the checksum.
struct Reader<'a> {
    /// Everything after the header and before the checksum.
    rest: &'a [u8],
    /// The whole input, for the checksum check in [`Reader::close`].
    all: &'a [u8],
}

impl<'a> Reader<'a> {
    /// Checks magic and version and positions the cursor after them.
    fn open(
        bytes: &'a [u8],
        magic: &[u8; 6],
        kind: &'static str,
    ) -> Result<Reader<'a>, DecodeError> {
        let head = &bytes[..bytes.len().min(magic.len())];
        if head != &magic[..head.len()] {
            return Err(DecodeError::BadMagic { expected: kind });
        }
        let mut r = Reader {
            rest: bytes,
            all: bytes,
        };
        r.take(magic.len(), "magic")?;
        let version = u16::from_le_bytes(r.array("format version")?);
        if version != FORMAT_VERSION {
            return Err(DecodeError::UnsupportedVersion {
                found: version,
                supported: FORMAT_VERSION,
            });
        }
        Ok(r)
    }

    /// Bytes still available to fields (the last 8 bytes are reserved for the checksum).
    fn available(&self) -> usize {
        self.rest.len().saturating_sub(CHECKSUM_LEN)
    }

    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], DecodeError> {
        let available = self.available();
        if n > available {
            return Err(DecodeError::Truncated {
                what,
                needed: n,
                available,
            });
        }
        let (head, tail) = self.rest.split_at(n);
        self.rest = tail;
        Ok(head)
    }

    fn array<const N: usize>(&mut self, what: &'static str) -> Result<[u8; N], DecodeError> {
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N, what)?);
        Ok(out)
    }

    fn u64(&mut self, what: &'static str) -> Result<u64, DecodeError> {
        Ok(u64::from_le_bytes(self.array(what)?))
    }

    fn usize(&mut self, what: &'static str) -> Result<usize, DecodeError> {
        let value = self.u64(what)?;
        usize::try_from(value).map_err(|_| DecodeError::ValueOutOfRange { what, value })
    }

    fn f64(&mut self, what: &'static str) -> Result<f64, DecodeError> {
        Ok(f64::from_bits(self.u64(what)?))
    }

    /// A presence flag that also tells the dimension: 0 absent, 1 (2D) or 2 (3D).
    fn kind(&mut self, what: &'static str) -> Result<u8, DecodeError> {
        match self.array::<1>(what)?[0] {
            value @ 0..=2 => Ok(value),
            value => Err(DecodeError::BadFlag { what, value }),
        }
    }

    fn flag(&mut self, what: &'static str) -> Result<bool, DecodeError> {
        match self.array::<1>(what)?[0] {
            0 => Ok(false),
            1 => Ok(true),
            value => Err(DecodeError::BadFlag { what, value }),
        }
    }

    /// Reads an element count and checks that that many elements of `element_size` bytes
    /// fit in what remains, so the caller may allocate for them.
    fn count(&mut self, what: &'static str, element_size: usize) -> Result<usize, DecodeError> {
        let declared = self.u64(what)?;
        let available = self.available();
        let fits = usize::try_from(declared)
            .ok()
            .and_then(|c| c.checked_mul(element_size))
            .is_some_and(|bytes| bytes <= available);
        if !fits {
            return Err(DecodeError::LengthOverflow {
                what,
                declared,
                element_size,
                available,
            });
        }
        // `fits` implies the conversion succeeded.
        usize::try_from(declared).map_err(|_| DecodeError::ValueOutOfRange {
            what,
            value: declared,
        })
    }

    fn f64s(&mut self, what: &'static str) -> Result<Vec<f64>, DecodeError> {
        let count = self.count(what, 8)?;
        let data = self.take(8 * count, what)?;
        Ok(data
            .chunks_exact(8)
            .map(|c| {
                let mut b = [0u8; 8];
                b.copy_from_slice(c);
                f64::from_bits(u64::from_le_bytes(b))
            })
            .collect())
    }

    fn opt_f64s(&mut self, what: &'static str) -> Result<Option<Vec<f64>>, DecodeError> {
        if self.flag(what)? {
            self.f64s(what).map(Some)
        } else {
            Ok(None)
        }
    }

    /// Requires that exactly the checksum remains and that it matches.
    fn close(self) -> Result<(), DecodeError> {
        if self.rest.len() < CHECKSUM_LEN {
            return Err(DecodeError::Truncated {
                what: "checksum",
                needed: CHECKSUM_LEN,
                available: self.rest.len(),
            });
        }
        if self.rest.len() > CHECKSUM_LEN {
            return Err(DecodeError::TrailingBytes {
                count: self.rest.len() - CHECKSUM_LEN,
            });
        }
        let body = &self.all[..self.all.len() - CHECKSUM_LEN];
        let mut stored = [0u8; CHECKSUM_LEN];
        stored.copy_from_slice(self.rest);
        let stored = u64::from_le_bytes(stored);
        let computed = checksum(body);
        if stored != computed {
            return Err(DecodeError::ChecksumMismatch { stored, computed });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
