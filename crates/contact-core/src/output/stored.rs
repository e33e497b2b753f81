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
//! | `sigma` | presence flag; if present `u64` triangle count, then per triangle `f64` σ_xx, σ_yy, σ_xy |
//! | `von_mises` | presence flag; if present `u64` count, then count × `f64` |
//! | `contact` | presence flag; if present `u64` count, then per node: `u64` node, `f64` slip velocity, `f64` friction traction, `f64` bound, `u8` slipping (0 or 1) |
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

use crate::solve::stepper::{ContactNode, State, StepFields};
use sha2::{Digest, Sha256};

/// Magic bytes that open an encoded [`StepFields`].
pub const STEP_MAGIC: &[u8; 6] = b"CSSTEP";
/// Magic bytes that open an encoded [`State`] (checkpoint).
pub const STATE_MAGIC: &[u8; 6] = b"CSSTAT";
/// The format version written by [`encode_step`] and [`encode_state`], and the only one read.
pub const FORMAT_VERSION: u16 = 1;

const CHECKSUM_LEN: usize = 8;
/// Bytes of one contact-node record: node, three `f64`s and the slipping flag.
const CONTACT_RECORD_LEN: usize = 8 + 3 * 8 + 1;

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
    #[error("invalid {what} flag {value} (expected 0 or 1)")]
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
    let arrays = [&f.u, &f.w, &f.zeta, &f.von_mises]
        .iter()
        .map(|a| a.as_ref().map_or(0, |v| 8 + 8 * v.len()))
        .sum::<usize>();
    let sigma = f.sigma.as_ref().map_or(0, |s| 8 + 24 * s.len());
    let contact = f
        .contact
        .as_ref()
        .map_or(0, |c| 8 + CONTACT_RECORD_LEN * c.len());
    let mut w = Writer::with_capacity(6 + 2 + 16 + 6 + arrays + sigma + contact + CHECKSUM_LEN);
    w.bytes(STEP_MAGIC);
    w.u16(FORMAT_VERSION);
    w.u64(f.n as u64);
    w.f64(f.t);
    w.opt_f64s(f.u.as_deref());
    w.opt_f64s(f.w.as_deref());
    w.opt_f64s(f.zeta.as_deref());
    match &f.sigma {
        None => w.u8(0),
        Some(s) => {
            w.u8(1);
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
            w.u8(1);
            w.u64(c.len() as u64);
            for node in c {
                w.u64(node.node as u64);
                w.f64(node.slip_velocity);
                w.f64(node.friction_traction);
                w.f64(node.bound);
                w.u8(u8::from(node.slipping));
            }
        }
    }
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
    let sigma = if r.flag("sigma presence")? {
        let count = r.count("sigma", 24)?;
        let mut s = Vec::with_capacity(count);
        for _ in 0..count {
            s.push([r.f64("sigma")?, r.f64("sigma")?, r.f64("sigma")?]);
        }
        Some(s)
    } else {
        None
    };
    let von_mises = r.opt_f64s("von_mises")?;
    let contact = if r.flag("contact presence")? {
        let count = r.count("contact", CONTACT_RECORD_LEN)?;
        let mut c = Vec::with_capacity(count);
        for _ in 0..count {
            c.push(ContactNode {
                node: r.usize("contact node")?,
                slip_velocity: r.f64("contact slip velocity")?,
                friction_traction: r.f64("contact friction traction")?,
                bound: r.f64("contact bound")?,
                slipping: r.flag("contact slipping")?,
            });
        }
        Some(c)
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
    r.close()?;
    Ok(State {
        step,
        u,
        zeta,
        contact_velocity,
        damage_active,
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
mod tests {
    use super::*;
    use proptest::prelude::*;

    use crate::test_rng::Rng;

    /// Finite values with varied exponents and signs.
    trait Values {
        fn f64(&mut self) -> f64;
        fn f64s(&mut self, n: usize) -> Vec<f64>;
    }

    impl Values for Rng {
        fn f64(&mut self) -> f64 {
            loop {
                let v = f64::from_bits(self.next_u64());
                if v.is_finite() {
                    return v;
                }
            }
        }

        fn f64s(&mut self, n: usize) -> Vec<f64> {
            (0..n).map(|_| self.f64()).collect()
        }
    }

    fn full_fields(rng: &mut Rng, nodes: usize, triangles: usize) -> StepFields {
        StepFields {
            n: 17,
            t: 0.17,
            u: Some(rng.f64s(2 * nodes)),
            w: Some(rng.f64s(2 * nodes)),
            zeta: Some(rng.f64s(nodes)),
            sigma: Some(
                (0..triangles)
                    .map(|_| [rng.f64(), rng.f64(), rng.f64()])
                    .collect(),
            ),
            von_mises: Some(rng.f64s(triangles)),
            contact: Some(
                (0..3)
                    .map(|i| ContactNode {
                        node: i * 5,
                        slip_velocity: rng.f64(),
                        friction_traction: rng.f64(),
                        bound: rng.f64(),
                        slipping: i % 2 == 0,
                    })
                    .collect(),
            ),
        }
    }

    fn empty_fields() -> StepFields {
        StepFields {
            n: 0,
            t: 0.0,
            u: None,
            w: None,
            zeta: None,
            sigma: None,
            von_mises: None,
            contact: None,
        }
    }

    /// Bit-exact equality (PartialEq on f64 would accept 0.0 == -0.0).
    fn bits(f: &StepFields) -> Vec<u64> {
        let mut out = vec![f.n as u64, f.t.to_bits()];
        for a in [&f.u, &f.w, &f.zeta, &f.von_mises] {
            match a {
                None => out.push(u64::MAX),
                Some(v) => {
                    out.push(v.len() as u64);
                    out.extend(v.iter().map(|x| x.to_bits()));
                }
            }
        }
        match &f.sigma {
            None => out.push(u64::MAX),
            Some(s) => {
                out.push(s.len() as u64);
                out.extend(s.iter().flatten().map(|x| x.to_bits()));
            }
        }
        match &f.contact {
            None => out.push(u64::MAX),
            Some(c) => {
                out.push(c.len() as u64);
                for n in c {
                    out.extend([
                        n.node as u64,
                        n.slip_velocity.to_bits(),
                        n.friction_traction.to_bits(),
                        n.bound.to_bits(),
                        u64::from(n.slipping),
                    ]);
                }
            }
        }
        out
    }

    #[test]
    fn full_step_round_trips_bit_exactly() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        let f = full_fields(&mut rng, 15, 16);
        let bytes = encode_step(&f);
        assert_eq!(&bytes[..6], STEP_MAGIC);
        let back = decode_step(&bytes).unwrap();
        assert_eq!(back, f);
        assert_eq!(bits(&back), bits(&f));
    }

    #[test]
    fn empty_and_partial_steps_round_trip() {
        let f = empty_fields();
        let bytes = encode_step(&f);
        // magic + version + n + t + 6 flags + checksum
        assert_eq!(bytes.len(), 6 + 2 + 8 + 8 + 6 + 8);
        assert_eq!(decode_step(&bytes).unwrap(), f);

        let mut rng = Rng(42);
        let full = full_fields(&mut rng, 6, 4);
        // Each field alone, and present-but-empty arrays.
        let partials = [
            StepFields {
                u: full.u.clone(),
                ..empty_fields()
            },
            StepFields {
                zeta: full.zeta.clone(),
                von_mises: Some(Vec::new()),
                ..empty_fields()
            },
            StepFields {
                sigma: full.sigma.clone(),
                contact: Some(Vec::new()),
                ..empty_fields()
            },
            StepFields {
                n: usize::MAX,
                t: -0.0,
                contact: full.contact.clone(),
                w: Some(Vec::new()),
                ..empty_fields()
            },
        ];
        for f in partials {
            let back = decode_step(&encode_step(&f)).unwrap();
            assert_eq!(bits(&back), bits(&f));
        }
    }

    #[test]
    fn state_round_trips_bit_exactly() {
        let mut rng = Rng(7);
        let s = State {
            step: 123_456,
            u: rng.f64s(30),
            zeta: rng.f64s(15),
            contact_velocity: rng.f64s(4),
            damage_active: vec![0, 1, 2, 0, 2],
        };
        let bytes = encode_state(&s);
        assert_eq!(&bytes[..6], STATE_MAGIC);
        let back = decode_state(&bytes).unwrap();
        assert_eq!(back.step, s.step);
        let b = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(b(&back.u), b(&s.u));
        assert_eq!(b(&back.zeta), b(&s.zeta));
        assert_eq!(b(&back.contact_velocity), b(&s.contact_velocity));
        assert_eq!(back.damage_active, s.damage_active);

        let empty = State::default();
        assert_eq!(decode_state(&encode_state(&empty)).unwrap(), empty);
    }

    #[test]
    fn step_and_state_are_not_confused() {
        let s = State {
            step: 1,
            u: vec![1.0],
            zeta: vec![1.0],
            ..State::default()
        };
        assert_eq!(
            decode_step(&encode_state(&s)),
            Err(DecodeError::BadMagic { expected: "CSSTEP" })
        );
        assert_eq!(
            decode_state(&encode_step(&empty_fields())),
            Err(DecodeError::BadMagic { expected: "CSSTAT" })
        );
    }

    #[test]
    fn every_single_byte_corruption_is_detected() {
        let mut rng = Rng(3);
        let f = StepFields {
            contact: Some(full_fields(&mut rng, 1, 1).contact.unwrap()[..2].to_vec()),
            ..full_fields(&mut rng, 2, 2)
        };
        let bytes = encode_step(&f);
        for i in 0..bytes.len() {
            for delta in [0x01u8, 0x80, 0xff] {
                let mut bad = bytes.clone();
                bad[i] ^= delta;
                assert!(
                    decode_step(&bad).is_err(),
                    "flipping {delta:#x} at byte {i} was not detected"
                );
            }
        }
        let state = encode_state(&State {
            step: 3,
            u: vec![1.0, -2.0],
            zeta: vec![0.5],
            ..State::default()
        });
        for i in 0..state.len() {
            let mut bad = state.clone();
            bad[i] ^= 0x10;
            assert!(decode_state(&bad).is_err(), "byte {i}");
        }
    }

    #[test]
    fn every_truncation_and_extension_is_an_error() {
        let mut rng = Rng(11);
        let bytes = encode_step(&full_fields(&mut rng, 3, 2));
        for len in 0..bytes.len() {
            assert!(decode_step(&bytes[..len]).is_err(), "length {len}");
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert!(decode_step(&longer).is_err());

        let state = encode_state(&State {
            step: 2,
            u: vec![0.25; 4],
            zeta: vec![1.0; 2],
            contact_velocity: vec![0.5],
            damage_active: vec![1, 0],
        });
        for len in 0..state.len() {
            assert!(decode_state(&state[..len]).is_err(), "length {len}");
        }
    }

    #[test]
    fn errors_say_what_is_wrong() {
        let bytes = encode_step(&empty_fields());
        assert_eq!(
            decode_step(b"NOTSTEP......"),
            Err(DecodeError::BadMagic { expected: "CSSTEP" })
        );
        assert!(matches!(
            decode_step(b"CSS"),
            Err(DecodeError::Truncated { .. })
        ));

        let mut v2 = bytes.clone();
        v2[6] = 2;
        assert_eq!(
            decode_step(&v2),
            Err(DecodeError::UnsupportedVersion {
                found: 2,
                supported: 1
            })
        );

        let mut sum = bytes.clone();
        let last = sum.len() - 1;
        sum[last] ^= 1;
        assert!(matches!(
            decode_step(&sum),
            Err(DecodeError::ChecksumMismatch { .. })
        ));

        let mut flag = bytes.clone();
        flag[24] = 7; // the `u` presence flag
        assert_eq!(
            decode_step(&flag),
            Err(DecodeError::BadFlag {
                what: "u",
                value: 7
            })
        );
        assert!(decode_step(&flag).unwrap_err().to_string().contains("flag"));

        let mut extra = bytes[..bytes.len() - 8].to_vec();
        extra.push(0);
        let extra = with_checksum(extra);
        assert_eq!(
            decode_step(&extra),
            Err(DecodeError::TrailingBytes { count: 1 })
        );
    }

    fn with_checksum(mut body: Vec<u8>) -> Vec<u8> {
        let sum = checksum(&body);
        body.extend_from_slice(&sum.to_le_bytes());
        body
    }

    #[test]
    fn hostile_lengths_are_rejected_before_allocating() {
        // A `u` array declaring u64::MAX (and other huge) element counts, with a valid
        // checksum so only the length guard stands in the way.
        for declared in [u64::MAX, u64::MAX / 8 + 1, 1 << 40, 2] {
            let mut body = Vec::new();
            body.extend_from_slice(STEP_MAGIC);
            body.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
            body.extend_from_slice(&5u64.to_le_bytes());
            body.extend_from_slice(&0.5f64.to_le_bytes());
            body.push(1);
            body.extend_from_slice(&declared.to_le_bytes());
            body.extend_from_slice(&1.0f64.to_le_bytes());
            let err = decode_step(&with_checksum(body)).unwrap_err();
            assert!(
                matches!(err, DecodeError::LengthOverflow { what: "u", .. }),
                "{err}"
            );
        }
        // The same for every array of a checkpoint and for the contact records.
        let mut body = Vec::new();
        body.extend_from_slice(STATE_MAGIC);
        body.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
        body.extend_from_slice(&1u64.to_le_bytes());
        body.extend_from_slice(&0u64.to_le_bytes());
        body.extend_from_slice(&u64::MAX.to_le_bytes());
        assert!(matches!(
            decode_state(&with_checksum(body)),
            Err(DecodeError::LengthOverflow { what: "zeta", .. })
        ));
        let mut body = encode_step(&empty_fields());
        body.truncate(body.len() - 9); // drop checksum and the contact flag
        body.push(1);
        body.extend_from_slice(&(u64::MAX / 33).to_le_bytes());
        assert!(matches!(
            decode_step(&with_checksum(body)),
            Err(DecodeError::LengthOverflow {
                what: "contact",
                ..
            })
        ));
    }

    fn arb_f64s(max: usize) -> impl Strategy<Value = Option<Vec<f64>>> {
        proptest::option::of(proptest::collection::vec(any::<f64>(), 0..max))
    }

    fn arb_fields() -> impl Strategy<Value = StepFields> {
        let contact = proptest::collection::vec(
            (
                any::<usize>(),
                any::<f64>(),
                any::<f64>(),
                any::<f64>(),
                any::<bool>(),
            )
                .prop_map(
                    |(node, slip_velocity, friction_traction, bound, slipping)| ContactNode {
                        node,
                        slip_velocity,
                        friction_traction,
                        bound,
                        slipping,
                    },
                ),
            0..8,
        );
        (
            (any::<usize>(), any::<f64>()),
            (arb_f64s(40), arb_f64s(40), arb_f64s(20)),
            proptest::option::of(proptest::collection::vec(any::<[f64; 3]>(), 0..20)),
            arb_f64s(20),
            proptest::option::of(contact),
        )
            .prop_map(
                |((n, t), (u, w, zeta), sigma, von_mises, contact)| StepFields {
                    n,
                    t,
                    u,
                    w,
                    zeta,
                    sigma,
                    von_mises,
                    contact,
                },
            )
    }

    proptest! {
        #[test]
        fn random_steps_round_trip(f in arb_fields()) {
            let back = decode_step(&encode_step(&f)).unwrap();
            prop_assert_eq!(bits(&back), bits(&f));
        }

        #[test]
        fn random_states_round_trip(
            step in any::<usize>(),
            u in proptest::collection::vec(any::<f64>(), 0..50),
            zeta in proptest::collection::vec(any::<f64>(), 0..50),
        ) {
            let s = State { step, u, zeta, ..State::default() };
            let back = decode_state(&encode_state(&s)).unwrap();
            prop_assert_eq!(back.step, s.step);
            prop_assert!(back.u.iter().zip(&s.u).all(|(a, b)| a.to_bits() == b.to_bits()));
            prop_assert!(back.zeta.iter().zip(&s.zeta).all(|(a, b)| a.to_bits() == b.to_bits()));
            prop_assert_eq!((back.u.len(), back.zeta.len()), (s.u.len(), s.zeta.len()));
        }

        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..300)) {
            let _ = decode_step(&bytes);
            let _ = decode_state(&bytes);
        }

        #[test]
        fn random_bytes_after_a_valid_header_never_panic(
            tail in proptest::collection::vec(any::<u8>(), 0..300),
            fix_checksum in any::<bool>(),
        ) {
            for magic in [STEP_MAGIC, STATE_MAGIC] {
                let mut bytes = magic.to_vec();
                bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
                bytes.extend_from_slice(&tail);
                let bytes = if fix_checksum { with_checksum(bytes) } else { bytes };
                let _ = decode_step(&bytes);
                let _ = decode_state(&bytes);
            }
        }

        #[test]
        fn random_corruption_of_valid_steps_is_detected(
            f in arb_fields(),
            pos in any::<proptest::sample::Index>(),
            delta in 1u8..=255,
        ) {
            let mut bytes = encode_step(&f);
            let i = pos.index(bytes.len());
            bytes[i] ^= delta;
            prop_assert!(decode_step(&bytes).is_err());
        }
    }
}
