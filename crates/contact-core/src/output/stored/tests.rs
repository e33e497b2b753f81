//! Round trips bit for bit, and every corruption, truncation and hostile length rejected.

use super::*;
use proptest::prelude::*;
use proptest::test_runner::{RngAlgorithm, TestRng};

/// A reproducible random stream for the hand-built cases.
fn seeded(seed: u8) -> TestRng {
    TestRng::from_seed(RngAlgorithm::ChaCha, &[seed; 32])
}

/// Finite values with varied exponents and signs.
trait Values {
    fn f64(&mut self) -> f64;
    fn f64s(&mut self, n: usize) -> Vec<f64>;
}

impl Values for TestRng {
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

fn full_fields(rng: &mut TestRng, nodes: usize, triangles: usize) -> StepFields {
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
                    tangential_velocity: None,
                    traction: None,
                })
                .collect(),
        ),
        estimate: Some(rng.f64s(triangles)),
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
        estimate: None,
    }
}

/// Bit-exact equality (PartialEq on f64 would accept 0.0 == -0.0).
fn bits(f: &StepFields) -> Vec<u64> {
    let mut out = vec![f.n as u64, f.t.to_bits()];
    for a in [&f.u, &f.w, &f.zeta, &f.von_mises, &f.estimate] {
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
            out.extend(s.values().map(|x| x.to_bits()));
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
    let mut rng = seeded(0x9e);
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
    // magic + version + n + t + 7 flags + checksum
    assert_eq!(bytes.len(), 6 + 2 + 8 + 8 + 7 + 8);
    assert_eq!(decode_step(&bytes).unwrap(), f);
    // A step written before the estimate existed ends after the contact flag.
    let old = with_checksum(bytes[..bytes.len() - 9].to_vec());
    assert_eq!(decode_step(&old).unwrap(), f);

    let mut rng = seeded(42);
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
    let mut rng = seeded(7);
    let s = State {
        step: 123_456,
        u: rng.f64s(30),
        zeta: rng.f64s(15),
        contact_velocity: rng.f64s(4),
        damage_active: vec![0, 1, 2, 0, 2],
        damage_before: rng.f64s(15),
        w: rng.f64s(30),
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
    assert_eq!(b(&back.damage_before), b(&s.damage_before));

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
    let mut rng = seeded(3);
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
    let mut rng = seeded(11);
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
        damage_before: vec![0.75; 2],
        w: vec![0.5; 4],
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
    body.truncate(body.len() - 10); // drop checksum and the contact and estimate flags
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
                    tangential_velocity: None,
                    traction: None,
                },
            ),
        0..8,
    );
    (
        (any::<usize>(), any::<f64>()),
        (arb_f64s(40), arb_f64s(40), arb_f64s(20)),
        proptest::option::of(proptest::collection::vec(any::<[f64; 3]>(), 0..20)),
        (arb_f64s(20), arb_f64s(20)),
        proptest::option::of(contact),
    )
        .prop_map(
            |((n, t), (u, w, zeta), sigma, (von_mises, estimate), contact)| StepFields {
                n,
                t,
                u,
                w,
                zeta,
                sigma: sigma.map(Stress::Plane),
                von_mises,
                contact,
                estimate,
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
