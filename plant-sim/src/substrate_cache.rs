//! On-disk cache of a windowed strip's substrate offsets ([`ChainSubstrate`]). Solving them on
//! the window's full FE model took 500 ms of the sunroof's 690 ms start-up on 2026-12-06, paid
//! again by every run, sweep case and study case with the same strip and substrate. They depend
//! only on the window's model, the chain, the substrate's features and the code that solves and
//! tabulates them, so the file (beside the contact tables, in their format:
//! `table_cache::write_vecs`) is keyed by a hash of all of those; a loaded substrate is the
//! solved one bit for bit. A missing or unusable file is solved anew.

use std::path::{Path, PathBuf};

use strip::chain::{SubstrateProfile, WindowChain};
use strip::StripParams;

use crate::contact::chain::ChainSubstrate;
use crate::table_cache::{read_vecs, write_vecs};

const MAGIC: &[u8; 8] = b"RIGSUBS1";

/// FNV-1a of the inputs' text and the code that turns them into the offsets: the window's
/// model key (its parameters and the strip code's version), the chain's offsets and the
/// features as exact decimal (`{:?}` of an f64 round-trips), and the source of the solving and
/// tabulating code, so an edit to it solves anew.
fn key(window: &StripParams, chain: &WindowChain, element_m: f64, profile: &SubstrateProfile) -> u64 {
    let text = format!("{}|{chain:?}|{element_m:?}|{:?}", window.cache_key(), profile.features);
    let code = [
        include_str!("contact/chain.rs"),
        include_str!("substrate_cache.rs"),
        include_str!("../../strip/src/chain.rs"),
        include_str!("../../strip/src/model.rs"),
    ];
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in text.bytes().chain(code.iter().flat_map(|c| c.bytes())) {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The cache file of the substrate `profile` under `chain` on the window model `window`.
pub fn path(dir: &Path, window: &StripParams, chain: &WindowChain, element_m: f64, profile: &SubstrateProfile) -> PathBuf {
    dir.join(format!("substrate-{:016x}.bin", key(window, chain, element_m, profile)))
}

/// Write `s` to `path` atomically.
pub fn save(s: &ChainSubstrate, path: &Path) -> std::io::Result<()> {
    write_vecs(path, MAGIC, &s.to_vecs())
}

/// The substrate cached at `path` for `chain`; None when there is no usable file.
pub fn load(path: &Path, chain: &WindowChain, element_m: f64) -> Option<ChainSubstrate> {
    ChainSubstrate::from_vecs(read_vecs(path, MAGIC)?, chain, element_m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use strip::chain::Feature;

    /// A cached substrate loads bit for bit; a cut file, or one of another chain, does not load;
    /// another feature or window is another file.
    #[test]
    fn cached_offsets_load_bit_for_bit_and_keys_follow_their_inputs() {
        let chain = WindowChain::new(0.1, 0.04, 0.01, 0.001).unwrap();
        let mut v = ChainSubstrate::flat(&chain, 0.001).to_vecs();
        v.iter_mut().flatten().enumerate().for_each(|(i, x)| *x = (i as f64).sin() * 1e-5);
        let sub = ChainSubstrate::from_vecs(v.clone(), &chain, 0.001).unwrap();
        let dir = std::env::temp_dir().join(format!("substrate-cache-test-{}", std::process::id()));
        let window = StripParams { length_m: 0.04, ..StripParams::default() };
        let bump = |h: f64| SubstrateProfile { features: vec![Feature::Bump { center_m: 0.05, half_width_m: 0.01, height_m: h }] };
        let p = path(&dir, &window, &chain, 0.001, &bump(2e-4));
        save(&sub, &p).unwrap();
        let bits = |v: &[Vec<f64>]| v.iter().map(|x| x.iter().map(|y| y.to_bits()).collect::<Vec<_>>()).collect::<Vec<_>>();
        assert_eq!(bits(&load(&p, &chain, 0.001).unwrap().to_vecs()), bits(&v));
        let longer = WindowChain::new(0.2, 0.04, 0.01, 0.001).unwrap();
        assert!(load(&p, &longer, 0.001).is_none(), "another chain's sizes");
        assert_ne!(p, path(&dir, &window, &chain, 0.001, &bump(2.5e-4)));
        assert_ne!(p, path(&dir, &window, &longer, 0.001, &bump(2e-4)));
        assert_ne!(p, path(&dir, &StripParams { poisson: 0.45, ..window.clone() }, &chain, 0.001, &bump(2e-4)));
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 3]).unwrap();
        assert!(load(&p, &chain, 0.001).is_none(), "a cut file");
        let _ = std::fs::remove_dir_all(&dir);
    }
}
