//! NumPy .npz export of the reduced model for Python/MATLAB users. Layout (all float64 unless
//! noted, SI units, task frame; see README.md):
//!   A (n, n), B (n, m), C (p, n), D (p, m)   x' = A x + B u, y = C x + D u (balanced coordinates)
//!   top_xyz_m (m, 3)        node of input j and of output j (top u_y)
//!   bottom_xz_m (nb, 2)     node of output m + i (bottom y reaction on the strip, N)
//!   bottom_area_m2 (nb,)    tributary area: pressure = reaction / area
//!   centre_bottom (nc,) int64   indices into the bottom nodes on x = 0, ascending z
//!   input_map (m, 3)        [node row in top_xyz_m, direction (1 = y), sign (+1: force along +y)]
//!   output_map (p, 3)       [kind (0 top u_y, 1 bottom reaction), node row, direction (1 = y)]
//!   bulge_top_uy_m (m,), bulge_bottom_reaction_n (nb,)   static offsets of the substrate bulge
//!   hankel_singular_values (N_cb,)
//!   gauss_abc (3,)          a, b, c of (5.34) (x, z in mm)

use std::path::Path;

use anyhow::Context;
use npyz::WriterBuilder;

use crate::model::{StripModel, GAUSS_A, GAUSS_B, GAUSS_C};

type Npz = npyz::npz::NpzWriter<std::io::BufWriter<std::fs::File>>;

fn put<T: npyz::Serialize + npyz::AutoSerialize + Copy>(w: &mut Npz, name: &str, shape: &[u64], data: &[T]) -> anyhow::Result<()> {
    let opts = npyz::zip::write::FileOptions::default().compression_method(npyz::zip::CompressionMethod::Stored);
    let mut a = w.array::<T>(name, opts)?.default_dtype().shape(shape).begin_nd()?;
    a.extend(data.iter().copied())?;
    a.finish()?;
    Ok(())
}

fn put_f64(w: &mut Npz, name: &str, shape: &[u64], data: &[f64]) -> anyhow::Result<()> {
    put(w, name, shape, data)
}

fn put_i64(w: &mut Npz, name: &str, shape: &[u64], data: &[i64]) -> anyhow::Result<()> {
    put(w, name, shape, data)
}

fn row_major(m: &faer::Mat<f64>) -> Vec<f64> {
    (0..m.nrows()).flat_map(|i| (0..m.ncols()).map(move |j| (i, j))).map(|(i, j)| m[(i, j)]).collect()
}

/// Writes the model to `path` (.npz, row-major C-order arrays).
pub fn write_npz(model: &StripModel, path: &Path) -> anyhow::Result<()> {
    let mut w = npyz::npz::NpzWriter::create(path).with_context(|| format!("creating {}", path.display()))?;
    let (n, m, p) = (model.order() as u64, model.n_top() as u64, model.c.nrows() as u64);
    let nb = model.n_bottom() as u64;
    put_f64(&mut w, "A", &[n, n], &row_major(&model.a))?;
    put_f64(&mut w, "B", &[n, m], &row_major(&model.b))?;
    put_f64(&mut w, "C", &[p, n], &row_major(&model.c))?;
    put_f64(&mut w, "D", &[p, m], &row_major(&model.d))?;
    put_f64(&mut w, "top_xyz_m", &[m, 3], &model.top_xyz_m.iter().flatten().copied().collect::<Vec<_>>())?;
    put_f64(&mut w, "bottom_xz_m", &[nb, 2], &model.bottom_xz_m.iter().flatten().copied().collect::<Vec<_>>())?;
    put_f64(&mut w, "bottom_area_m2", &[nb], &model.bottom_area_m2)?;
    put_i64(
        &mut w,
        "centre_bottom",
        &[model.centre_bottom.len() as u64],
        &model.centre_bottom.iter().map(|&i| i as i64).collect::<Vec<_>>(),
    )?;
    let input_map: Vec<i64> = (0..m as i64).flat_map(|j| [j, 1, 1]).collect();
    put_i64(&mut w, "input_map", &[m, 3], &input_map)?;
    let output_map: Vec<i64> = (0..m as i64).flat_map(|j| [0, j, 1]).chain((0..nb as i64).flat_map(|i| [1, i, 1])).collect();
    put_i64(&mut w, "output_map", &[p, 3], &output_map)?;
    put_f64(&mut w, "bulge_top_uy_m", &[m], &model.bulge_top_uy_m)?;
    put_f64(&mut w, "bulge_bottom_reaction_n", &[nb], &model.bulge_bottom_reaction_n)?;
    put_f64(&mut w, "hankel_singular_values", &[model.hsv.len() as u64], &model.hsv)?;
    put_f64(&mut w, "gauss_abc", &[3], &[GAUSS_A, GAUSS_B, GAUSS_C])?;
    w.zip_writer().finish().context("finishing npz")?;
    Ok(())
}
