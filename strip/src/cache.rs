//! On-disk cache of built models, keyed by a hash of every parameter plus the code version.
//! Layout: b"STRIPMDL", u64 LE header length, JSON header, then raw little-endian f64 arrays
//! (A, B, C, D column-major; modal lambda, weights, B, C as re/im pairs; then top xyz, bottom xz,
//! bottom areas, bulge offsets, Hankel singular values).

use std::io::Write;
use std::path::{Path, PathBuf};

use faer::{c64, Mat};
use serde::{Deserialize, Serialize};

use crate::error::{Result, StripError};
use crate::model::{BuildInfo, ModalForm, StripModel};
use crate::params::StripParams;

const MAGIC: &[u8; 8] = b"STRIPMDL";

#[derive(Serialize, Deserialize)]
struct Header {
    /// Exact text of the parameters (compared as text: JSON float parsing need not round-trip).
    params_json: String,
    info: BuildInfo,
    order: usize,
    n_in: usize,
    n_out: usize,
    n_bottom: usize,
    modes: usize,
    n_hsv: usize,
    centre_bottom: Vec<usize>,
}

/// Cache directory: `$RIG_CACHE_DIR`, else `<workspace>/target/strip-cache` when run from the
/// workspace, else `~/.cache/rig/strip`.
pub fn cache_dir() -> PathBuf {
    if let Some(d) = std::env::var_os("RIG_CACHE_DIR") {
        return PathBuf::from(d).join("strip");
    }
    let ws = Path::new(env!("CARGO_MANIFEST_DIR")).parent().map(Path::to_path_buf);
    if let Some(ws) = ws {
        if ws.join("Cargo.toml").is_file() && ws.join("target").is_dir() {
            return ws.join("target").join("strip-cache");
        }
    }
    let home = std::env::var_os("HOME").map(PathBuf::from).unwrap_or_else(|| PathBuf::from("."));
    home.join(".cache").join("rig").join("strip")
}

/// Cache file of a parameter set: the file of its reference bump
/// ([`StripParams::with_reference_bulge`]), which serves every height of that bump.
pub fn cache_path(dir: &Path, p: &StripParams) -> PathBuf {
    dir.join(format!("strip-{}.bin", p.with_reference_bulge().cache_key()))
}

fn push_mat(buf: &mut Vec<u8>, m: &Mat<f64>) {
    for j in 0..m.ncols() {
        for i in 0..m.nrows() {
            buf.extend_from_slice(&m[(i, j)].to_le_bytes());
        }
    }
}

fn push_c(buf: &mut Vec<u8>, v: &[c64]) {
    for x in v {
        buf.extend_from_slice(&x.re.to_le_bytes());
        buf.extend_from_slice(&x.im.to_le_bytes());
    }
}

/// Writes `model` to `path` atomically (temporary file + rename). Only a model at the reference
/// bump is cached (what [`load`] expects in the file [`cache_path`] names).
pub fn save(model: &StripModel, path: &Path) -> Result<()> {
    let io = |e| StripError::Io { path: path.display().to_string(), cause: e };
    if model.params != model.params.with_reference_bulge() {
        return Err(StripError::Cache {
            path: path.display().to_string(),
            detail: format!(
                "only the reference bump's model is cached (bump {} m, the model's {} m)",
                StripParams::BULGE_REFERENCE_M,
                model.params.bulge_amplitude_m
            ),
        });
    }
    let h = Header {
        params_json: serde_json::to_string(&model.params).expect("params serialise"),
        info: model.info.clone(),
        order: model.order(),
        n_in: model.n_top(),
        n_out: model.c.nrows(),
        n_bottom: model.n_bottom(),
        modes: model.modal.modes(),
        n_hsv: model.hsv.len(),
        centre_bottom: model.centre_bottom.clone(),
    };
    let json = serde_json::to_vec(&h).expect("header serialises");
    let mut buf = Vec::with_capacity(16 + json.len() + 8 * (model.d.nrows() * model.d.ncols() * 3));
    buf.extend_from_slice(MAGIC);
    buf.extend_from_slice(&(json.len() as u64).to_le_bytes());
    buf.extend_from_slice(&json);
    for m in [&model.a, &model.b, &model.c, &model.d] {
        push_mat(&mut buf, m);
    }
    push_c(&mut buf, &model.modal.lam);
    for w in &model.modal.weight {
        buf.extend_from_slice(&w.to_le_bytes());
    }
    push_c(&mut buf, &model.modal.b);
    push_c(&mut buf, &model.modal.c);
    let vecs: [&[f64]; 6] = [
        model.top_xyz_m.as_flattened(),
        model.bottom_xz_m.as_flattened(),
        &model.bottom_area_m2,
        &model.bulge_top_uy_m,
        &model.bulge_bottom_reaction_n,
        &model.hsv,
    ];
    for v in vecs {
        for x in v {
            buf.extend_from_slice(&x.to_le_bytes());
        }
    }
    if let Some(parent) = path.parent() {
        std::fs::create_dir_all(parent).map_err(io)?;
    }
    // Unique per writer, threads of one process included: two threads saving the same model
    // (parallel tests on an empty cache) must not share, truncate or rename each other's file.
    static SAVES: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let n = SAVES.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let tmp = path.with_extension(format!("tmp{}-{n}", std::process::id()));
    let mut f = std::fs::File::create(&tmp).map_err(io)?;
    f.write_all(&buf).map_err(io)?;
    drop(f);
    std::fs::rename(&tmp, path).map_err(io)?;
    Ok(())
}

struct Reader<'a> {
    b: &'a [u8],
    pos: usize,
    path: &'a Path,
}

impl Reader<'_> {
    fn f64s(&mut self, n: usize) -> Result<&[u8]> {
        let end = self.pos + 8 * n;
        if end > self.b.len() {
            return Err(StripError::Cache { path: self.path.display().to_string(), detail: "truncated".into() });
        }
        let s = &self.b[self.pos..end];
        self.pos = end;
        Ok(s)
    }
    fn mat(&mut self, r: usize, c: usize) -> Result<Mat<f64>> {
        let s = self.f64s(r * c)?;
        Ok(Mat::from_fn(r, c, |i, j| {
            let k = 8 * (j * r + i);
            f64::from_le_bytes(s[k..k + 8].try_into().unwrap())
        }))
    }
    fn vec(&mut self, n: usize) -> Result<Vec<f64>> {
        Ok(self.f64s(n)?.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect())
    }
    fn cvec(&mut self, n: usize) -> Result<Vec<c64>> {
        let s = self.f64s(2 * n)?;
        Ok(s.chunks_exact(16)
            .map(|c| c64::new(f64::from_le_bytes(c[..8].try_into().unwrap()), f64::from_le_bytes(c[8..].try_into().unwrap())))
            .collect())
    }
}

/// Loads a cached model; `Ok(None)` if the file does not exist.
pub fn load(path: &Path, expect: &StripParams) -> Result<Option<StripModel>> {
    let bytes = match std::fs::read(path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(StripError::Io { path: path.display().to_string(), cause: e }),
    };
    let bad = |d: &str| StripError::Cache { path: path.display().to_string(), detail: d.to_string() };
    if bytes.len() < 16 || &bytes[..8] != MAGIC {
        return Err(bad("not a strip model cache file"));
    }
    let hl = u64::from_le_bytes(bytes[8..16].try_into().unwrap()) as usize;
    let h: Header =
        serde_json::from_slice(bytes.get(16..16 + hl).ok_or_else(|| bad("truncated header"))?).map_err(|e| bad(&format!("header: {e}")))?;
    let expect_json = serde_json::to_string(expect).expect("params serialise");
    if h.params_json != expect_json || h.info.code_version != crate::CODE_VERSION {
        return Err(bad("parameters or code version differ from the request (hash collision or stale file)"));
    }
    let mut r = Reader { b: &bytes, pos: 16 + hl, path };
    let a = r.mat(h.order, h.order)?;
    let b = r.mat(h.order, h.n_in)?;
    let c = r.mat(h.n_out, h.order)?;
    let d = r.mat(h.n_out, h.n_in)?;
    let lam = r.cvec(h.modes)?;
    let weight = r.vec(h.modes)?;
    let mb = r.cvec(h.modes * h.n_in)?;
    let mc = r.cvec(h.modes * h.n_out)?;
    let top = r.vec(3 * h.n_in)?;
    let bxz = r.vec(2 * h.n_bottom)?;
    let bottom_area_m2 = r.vec(h.n_bottom)?;
    let bulge_top_uy_m = r.vec(h.n_in)?;
    let bulge_bottom_reaction_n = r.vec(h.n_bottom)?;
    let hsv = r.vec(h.n_hsv)?;
    if r.pos != bytes.len() {
        return Err(bad("trailing bytes"));
    }
    Ok(Some(StripModel {
        params: expect.clone(),
        a,
        b,
        c,
        d,
        top_xyz_m: top.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        bottom_xz_m: bxz.chunks_exact(2).map(|c| [c[0], c[1]]).collect(),
        bottom_area_m2,
        centre_bottom: h.centre_bottom,
        bulge_top_uy_m,
        bulge_bottom_reaction_n,
        hsv,
        modal: ModalForm { lam, weight, b: mb, c: mc },
        info: h.info,
    }))
}

impl StripModel {
    /// Loads the model for `p` from the cache directory, or builds (with a progress display) and
    /// stores it. A corrupt or stale cache file is rebuilt and overwritten. The cache holds the
    /// reference bump's model (one file for every height of a bump shape), scaled to `p`'s height
    /// ([`StripModel::with_bulge_of`]).
    pub fn load_or_build(p: &StripParams) -> Result<StripModel> {
        Self::load_or_build_in(&cache_dir(), p)
    }

    pub fn load_or_build_in(dir: &Path, p: &StripParams) -> Result<StripModel> {
        p.validate()?;
        let reference = p.with_reference_bulge();
        let path = cache_path(dir, p);
        match load(&path, &reference) {
            Ok(Some(m)) => return Ok(m.with_bulge_of(p)),
            Ok(None) => {}
            Err(e) => tracing::warn!(error = %e, "ignoring unusable strip model cache file"),
        }
        let model = {
            let _progress = crate::progress::Progress::start("building strip model");
            StripModel::build(&reference)?
        };
        save(&model, &path)?;
        tracing::info!(path = %path.display(), "strip model cached");
        Ok(model.with_bulge_of(p))
    }
}
