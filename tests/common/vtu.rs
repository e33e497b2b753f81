//! The data arrays of a VTU file as VTK reads them, in either encoding the service writes:
//! raw (base64 of a UInt64 byte count and the bytes) or, with
//! `compressor="vtkZLibDataCompressor"` on the root, zlib (base64 of the header `[blocks,
//! block size, last block size, compressed sizes…]`, then base64 of the zlib blocks).

use base64::engine::general_purpose::STANDARD;
use base64::Engine;
use std::io::Read;

/// Whether the document's arrays are zlib-compressed (its root names the compressor).
pub fn is_compressed(vtu: &str) -> bool {
    let root = vtu
        .split("<VTKFile")
        .nth(1)
        .and_then(|r| r.split('>').next())
        .expect("a VTKFile element");
    root.contains("compressor=\"vtkZLibDataCompressor\"")
}

/// The bytes of one array from its element text, every header checked against them.
pub fn decode(text: &str, compressed: bool) -> Vec<u8> {
    let text = text.trim();
    if !compressed {
        let raw = STANDARD.decode(text).expect("base64");
        let (head, data) = raw.split_at(8);
        assert_eq!(
            u64::from_le_bytes(head.try_into().unwrap()) as usize,
            data.len(),
            "byte-count header"
        );
        return data.to_vec();
    }
    let chars = |bytes: usize| bytes.div_ceil(3) * 4;
    let first = STANDARD.decode(&text[..chars(8)]).expect("base64");
    let blocks = u64::from_le_bytes(first[..8].try_into().unwrap()) as usize;
    let header_chars = chars(8 * (3 + blocks));
    let header: Vec<usize> = STANDARD
        .decode(&text[..header_chars])
        .expect("base64")
        .chunks_exact(8)
        .map(|c| u64::from_le_bytes(c.try_into().unwrap()) as usize)
        .collect();
    let compressed = STANDARD.decode(&text[header_chars..]).expect("base64");
    assert_eq!(compressed.len(), header[3..].iter().sum::<usize>());
    let mut data = Vec::new();
    let mut at = 0;
    for (i, &size) in header[3..].iter().enumerate() {
        let before = data.len();
        flate2::read::ZlibDecoder::new(&compressed[at..at + size])
            .read_to_end(&mut data)
            .expect("zlib");
        let expect = if i + 1 == blocks {
            header[2]
        } else {
            header[1]
        };
        assert_eq!(data.len() - before, expect, "block {i}");
        at += size;
    }
    data
}
