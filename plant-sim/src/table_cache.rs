//! On-disk cache of the contact tables ([`StripTables`]): building them is most of a lockstep
//! run's start-up (350-440 ms of 1.3 s on 2026-12-03, against 35 ms for loading the cached strip
//! model), and they depend only on the strip model and the substep. The file sits beside the
//! strip model's, keyed by the model's cache key (its parameters and the strip code's version),
//! the substep's bits and a hash of this crate's table code (`contact.rs`, this file), so a change
//! to either builds anew. Written atomically (temporary file, rename); raw little-endian values,
//! so a loaded table is the built one bit for bit. A missing or unusable file is rebuilt.

use std::io::Write;
use std::path::{Path, PathBuf};

use strip::StripParams;

use crate::contact::{StripTables, TableParts};

const MAGIC: &[u8; 8] = b"RIGCTBL2";

/// FNV-1a of the table code, so an edit to it invalidates every cached table.
fn code_hash() -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in include_str!("contact.rs").bytes().chain(include_str!("table_cache.rs").bytes()) {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0100_0000_01b3);
    }
    h
}

/// The cache file of the tables of the model `reference` (at the reference bump) and substep `h_s`.
pub fn path(dir: &Path, reference: &StripParams, h_s: f64) -> PathBuf {
    dir.join(format!("tables-{}-{:016x}-{:016x}.bin", reference.cache_key(), h_s.to_bits(), code_hash()))
}

/// Write `t` to `path` atomically.
pub fn save(t: &StripTables, path: &Path) -> std::io::Result<()> {
    write_vecs(path, MAGIC, t.parts().vecs())
}

/// The tables cached at `path` for `reference` and `h_s`; None when there is no usable file.
pub fn load(path: &Path, reference: &StripParams, h_s: f64) -> Option<StripTables> {
    StripTables::from_parts(reference.clone(), h_s, TableParts::from_vecs(read_vecs(path, MAGIC)?)?)
}

/// The cache files' format (here and `substrate_cache`): `magic`, then each vector as its length
/// (u64) and its values, little-endian. Written to a temporary file, synced and renamed, so a
/// reader never sees half a file.
pub(crate) fn write_vecs(path: &Path, magic: &[u8; 8], vecs: &[Vec<f64>]) -> std::io::Result<()> {
    let mut buf = Vec::with_capacity(8 * vecs.iter().map(|v| v.len() + 1).sum::<usize>() + 8);
    buf.extend_from_slice(magic);
    for v in vecs {
        buf.extend_from_slice(&(v.len() as u64).to_le_bytes());
        for x in v {
            buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let tmp = path.with_extension(format!("tmp{}", std::process::id()));
    {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(&buf)?;
        f.sync_all()?;
    }
    std::fs::rename(&tmp, path)
}

/// [`write_vecs`]' vectors from `path`, bit for bit; None for a missing, foreign or cut file.
/// Each vector is read straight into its own buffer: one copy from the page cache, where reading
/// the whole file first and converting it paid a second buffer, its page faults and the copy
/// (the 4 MB contact tables were most of a lockstep run's start-up, 9-15 ms, 2026-12-07).
pub(crate) fn read_vecs(path: &Path, magic: &[u8; 8]) -> Option<Vec<Vec<f64>>> {
    use std::io::Read;
    let mut f = std::io::BufReader::with_capacity(64, std::fs::File::open(path).ok()?);
    let mut left = f.get_ref().metadata().ok()?.len().checked_sub(8)?;
    let mut head = [0u8; 8];
    f.read_exact(&mut head).ok()?;
    if &head != magic {
        return None;
    }
    let mut vecs = Vec::new();
    while left > 0 {
        f.read_exact(&mut head).ok()?;
        left = left.checked_sub(8)?;
        let n = u64::from_le_bytes(head);
        // a length the file cannot hold is a cut or foreign file, not an allocation
        left = left.checked_sub(n.checked_mul(8)?)?;
        let mut v = vec![0.0f64; usize::try_from(n).ok()?];
        // SAFETY: the bytes of v's n f64 values, 8 n of them, initialised; any bit pattern is
        // an f64.
        let raw = unsafe { std::slice::from_raw_parts_mut(v.as_mut_ptr().cast::<u8>(), v.len() * 8) };
        f.read_exact(raw).ok()?;
        // little-endian on disk (a no-op on a little-endian host)
        v.iter_mut().for_each(|x| *x = f64::from_bits(u64::from_le(x.to_bits())));
        vecs.push(v);
    }
    Some(vecs)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cached_tables_load_bit_for_bit_and_a_bad_file_is_rebuilt() {
        let model = crate::contact::tests::coarse();
        let h = 1e-4;
        let built = StripTables::new(&model, h);
        let dir = std::env::temp_dir().join(format!("table-cache-test-{}", std::process::id()));
        let path = path(&dir, &model.params, h);
        save(&built, &path).unwrap();
        let loaded = load(&path, &model.params, h).expect("cached tables load");
        let bits = |t: &StripTables| t.parts().vecs().iter().map(|v| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>()).collect::<Vec<_>>();
        assert_eq!(bits(&loaded), bits(&built));
        assert_eq!(loaded.params(), built.params());
        // Another substep, a truncated file: no tables (the caller builds them).
        assert!(load(&path, &model.params, 2e-4).is_none());
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - 5]).unwrap();
        assert!(load(&path, &model.params, h).is_none());
        // A length the file cannot hold (a huge one, one 8 bytes too long), another magic: none,
        // and nothing allocated for the huge one.
        for n in [u64::MAX / 8, 2] {
            let mut b = MAGIC.to_vec();
            b.extend_from_slice(&n.to_le_bytes());
            b.extend_from_slice(&1.5f64.to_le_bytes());
            std::fs::write(&path, &b).unwrap();
            assert!(read_vecs(&path, MAGIC).is_none(), "length {n}");
        }
        let mut b = MAGIC.to_vec();
        b.extend_from_slice(&1u64.to_le_bytes());
        b.extend_from_slice(&1.5f64.to_le_bytes());
        std::fs::write(&path, &b).unwrap();
        assert_eq!(read_vecs(&path, MAGIC), Some(vec![vec![1.5]]));
        assert!(read_vecs(&path, b"RIGOTHER").is_none());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
