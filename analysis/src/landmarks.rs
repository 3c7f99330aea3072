//! Range-bearing observations of known landmarks (CONTRACT section 2): `OBS.csv`
//! with `t,id,range,bearing` (bearing relative to the robot heading) and `MAP.csv`
//! with `id,x,y`. Predicted through the model's `landmark` observation (seed 001
//! eq. 6) at the dead-reckoned pose interpolated to the observation time, so the
//! innovations (seed 001's EKF update) measure the model error, and calibration
//! can use them with the exact sensitivities.
use crate::dataset::Run;
use crate::deadreckon::Track;
use crate::log::{read_csv, wrap, LogError};
use crate::model::Runner;
use kinegen_model::spec::ObservationRole::RangeBearing;
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;

/// Range and bearing noise (m, rad) when the spec's `landmark` observation
/// declares none.
pub const DEFAULT_SIGMA: [f64; 2] = [0.05, 0.02];

/// One range-bearing observation, with the mapped landmark it refers to.
#[derive(Debug, Clone)]
pub struct LandmarkObs {
    pub t: f64,
    pub id: String,
    pub xl: f64,
    pub yl: f64,
    pub range: f64,
    pub bearing: f64,
}

/// Landmark positions by id.
#[derive(Debug, Clone, Default)]
pub struct Map {
    pub ids: Vec<String>,
    pub xy: HashMap<String, [f64; 2]>,
}

/// Read `MAP.csv` (`id,x,y`); ids are text and must be unique.
pub fn read_map(path: &Path) -> Result<Map, LogError> {
    let (h, mut rdr) = read_csv(path, "landmark map")?;
    let cols = h.require(&["id", "x", "y"])?;
    let (id_i, x_i, y_i) = (cols[0], cols[1], cols[2]);
    let mut map = Map::default();
    for (n, rec) in rdr.records().enumerate() {
        let (line, rec) = h.record(n, rec)?;
        let id = h.text(line, &rec, id_i)?.to_string();
        if id.is_empty() {
            return Err(h.err(Some(line), Some("id"), "empty landmark id"));
        }
        let xy = [h.number(line, &rec, x_i)?, h.number(line, &rec, y_i)?];
        if map.xy.insert(id.clone(), xy).is_some() {
            return Err(h.err(
                Some(line),
                Some("id"),
                format!("landmark `{id}` is listed twice"),
            ));
        }
        map.ids.push(id);
    }
    if map.ids.is_empty() {
        return Err(h.err(None, None, "the map lists no landmarks"));
    }
    Ok(map)
}

/// Read `OBS.csv` (`t,id,range,bearing`): time non-decreasing (several landmarks
/// may be seen at one instant), range positive, every id in the map.
pub fn read_observations(
    path: &Path,
    map: &Map,
    map_path: &Path,
) -> Result<Vec<LandmarkObs>, LogError> {
    let (h, mut rdr) = read_csv(path, "landmark observations")?;
    let cols = h.require(&["t", "id", "range", "bearing"])?;
    let (t_i, id_i, range_i, bearing_i) = (cols[0], cols[1], cols[2], cols[3]);
    let mut out: Vec<LandmarkObs> = Vec::new();
    for (n, rec) in rdr.records().enumerate() {
        let (line, rec) = h.record(n, rec)?;
        let t = h.number(line, &rec, t_i)?;
        if let Some(prev) = out.last() {
            if t < prev.t {
                return Err(h.err(
                    Some(line),
                    Some("t"),
                    format!("time goes backwards: {t} follows {}", prev.t),
                ));
            }
        }
        let id = h.text(line, &rec, id_i)?.to_string();
        let Some(&[xl, yl]) = map.xy.get(&id) else {
            return Err(h.err(
                Some(line),
                Some("id"),
                format!("landmark `{id}` is not in the map {}", map_path.display()),
            ));
        };
        let range = h.number(line, &rec, range_i)?;
        if range <= 0.0 {
            return Err(h.err(
                Some(line),
                Some("range"),
                format!("range {range} is not positive"),
            ));
        }
        let bearing = h.number(line, &rec, bearing_i)?;
        out.push(LandmarkObs {
            t,
            id,
            xl,
            yl,
            range,
            bearing,
        });
    }
    if out.is_empty() {
        return Err(h.err(None, None, "no observations"));
    }
    Ok(out)
}

/// Range-bearing observations from a bag's landmark topic (see
/// [`crate::bag::LandmarkSource`]), every id in the map, ordered by time.
pub fn from_detections(
    bag: &Path,
    found: &[crate::bag::Detection],
    map: &Map,
    map_path: &Path,
) -> Result<Vec<LandmarkObs>, LogError> {
    let mut out = Vec::with_capacity(found.len());
    for d in found {
        let Some(&[xl, yl]) = map.xy.get(&d.id) else {
            return Err(LogError::new(
                bag,
                None,
                None,
                format!(
                    "topic `{}` message {} (counting from 0): landmark `{}` is not in the map {}",
                    d.topic,
                    d.index,
                    d.id,
                    map_path.display()
                ),
            ));
        };
        out.push(LandmarkObs {
            t: d.t,
            id: d.id.clone(),
            xl,
            yl,
            range: d.range,
            bearing: d.bearing,
        });
    }
    out.sort_by(|a, b| a.t.total_cmp(&b.t));
    Ok(out)
}

/// The robot pose from landmarks seen while it stands still at the start (at
/// least two distinct landmarks before `t_until`): each observation places a
/// landmark in the robot frame, and the rigid transform that maps those points
/// onto the map is the pose (2-D Kabsch / Procrustes, closed form). Used when a
/// log has no ground truth.
pub fn pose_from_landmarks(obs: &[LandmarkObs], t_until: f64) -> Option<[f64; 3]> {
    let seen: Vec<&LandmarkObs> = obs.iter().filter(|o| o.t <= t_until).collect();
    let distinct: std::collections::HashSet<&str> = seen.iter().map(|o| o.id.as_str()).collect();
    if distinct.len() < 2 {
        return None;
    }
    let body: Vec<[f64; 2]> = seen
        .iter()
        .map(|o| [o.range * o.bearing.cos(), o.range * o.bearing.sin()])
        .collect();
    let world: Vec<[f64; 2]> = seen.iter().map(|o| [o.xl, o.yl]).collect();
    let n = seen.len() as f64;
    let mean = |v: &[[f64; 2]]| {
        [
            v.iter().map(|p| p[0]).sum::<f64>() / n,
            v.iter().map(|p| p[1]).sum::<f64>() / n,
        ]
    };
    let (mb, mw) = (mean(&body), mean(&world));
    let (mut sdot, mut scross) = (0.0, 0.0);
    for (b, w) in body.iter().zip(&world) {
        let (bx, by, wx, wy) = (b[0] - mb[0], b[1] - mb[1], w[0] - mw[0], w[1] - mw[1]);
        sdot += bx * wx + by * wy;
        scross += bx * wy - by * wx;
    }
    let th = scross.atan2(sdot);
    let (s, c) = th.sin_cos();
    Some([
        mw[0] - (c * mb[0] - s * mb[1]),
        mw[1] - (s * mb[0] + c * mb[1]),
        th,
    ])
}

/// The start pose that explains the range-bearing observations of the start
/// window through the model's own `landmark` observation (a sensor mounted off
/// the body origin included), by Gauss-Newton from `guess` (the closed-form
/// pose of a sensor at the origin, [`pose_from_landmarks`]); with its
/// derivative with respect to the parameters (3 x P, row-major), from the
/// implicit function theorem: d x0 / d p = -(Hx' W Hx)^-1 Hx' W Hp.
/// None when the model has no such observation or too few are seen.
pub fn start_from_landmarks(
    r: &Runner,
    p: &[f64],
    run: &Run,
    guess: [f64; 3],
) -> Option<([f64; 3], Vec<f64>)> {
    use nalgebra::{DMatrix, Matrix3, Vector3};
    let h = r.ir.observation_fn(RangeBearing, "")?;
    let hx = r.ir.observation_fn(RangeBearing, "_jac_x")?;
    let hp = r.ir.observation_fn(RangeBearing, "_jac_p")?;
    let until = run.start_window_end();
    let seen: Vec<&LandmarkObs> = run.landmarks.iter().filter(|o| o.t <= until).collect();
    let distinct: std::collections::HashSet<&str> = seen.iter().map(|o| o.id.as_str()).collect();
    if distinct.len() < 2 {
        return None;
    }
    let sigma = sigma(r);
    let w = [1.0 / (sigma[0] * sigma[0]), 1.0 / (sigma[1] * sigma[1])];
    let u = run.u.first()?;
    let np = p.len();
    let mut x = guess;
    // normal equations of the weighted observations at x: (Hx' W Hx, Hx' W r, Hx' W Hp)
    let normal = |x: &[f64; 3], with_p: bool| {
        let (mut a, mut b) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
        let mut c = DMatrix::zeros(3, if with_p { np } else { 0 });
        for o in &seen {
            let lm = [o.xl, o.yl];
            let pred = h.eval(&Runner::obs_args(h, x, u, p, &lm));
            let res = [o.range - pred[0], wrap(o.bearing - pred[1])];
            let jx = hx.eval(&Runner::obs_args(hx, x, u, p, &lm));
            let jp = with_p.then(|| hp.eval(&Runner::obs_args(hp, x, u, p, &lm)));
            for k in 0..2 {
                for i in 0..3 {
                    b[i] += jx[k * 3 + i] * w[k] * res[k];
                    for j in 0..3 {
                        a[(i, j)] += jx[k * 3 + i] * w[k] * jx[k * 3 + j];
                    }
                    if let Some(jp) = &jp {
                        for j in 0..np {
                            c[(i, j)] += jx[k * 3 + i] * w[k] * jp[k * np + j];
                        }
                    }
                }
            }
        }
        (a, b, c)
    };
    for _ in 0..20 {
        let (a, b, _) = normal(&x, false);
        let step: Vector3<f64> = a.try_inverse()? * b;
        if !step.iter().all(|v| v.is_finite()) {
            return None;
        }
        for i in 0..3 {
            x[i] += step[i];
        }
        if step.norm() < 1e-12 {
            break;
        }
    }
    let (a, _, c) = normal(&x, true);
    let d = -(a.try_inverse()? * c);
    // row-major 3 x P, as body_start gives it
    let d: Vec<f64> = (0..3)
        .flat_map(|i| (0..np).map(move |j| (i, j)))
        .map(|(i, j)| d[(i, j)])
        .collect();
    Some((x, d))
}

/// Range and bearing noise of the model's `landmark` observation (or the
/// defaults when it declares none).
pub fn sigma(r: &Runner) -> [f64; 2] {
    r.obs_sigma(RangeBearing)
        .filter(|s| s.len() == 2 && s.iter().all(|v| *v > 0.0))
        .map_or(DEFAULT_SIGMA, |s| [s[0], s[1]])
}

/// Where an observation falls on a track: (step j, fraction a, interpolated pose).
pub fn locate_on(run: &Run, track: &Track, t: f64) -> (usize, f64, [f64; 3]) {
    let (j, a) = run.locate(t);
    let a = a.clamp(0.0, 1.0);
    let (p0, p1) = (track.pose[j], track.pose[j + 1]);
    (j, a, [0, 1, 2].map(|i| p0[i] + a * (p1[i] - p0[i])))
}

/// Model prediction (range, bearing) of an observation from a track.
pub fn predict(
    r: &Runner,
    p: &[f64],
    run: &Run,
    track: &Track,
    o: &LandmarkObs,
) -> Option<[f64; 2]> {
    let h = r.ir.observation_fn(RangeBearing, "")?;
    let (j, _, x) = locate_on(run, track, o.t);
    let u = &run.u[j.min(run.steps() - 1)];
    let v = h.eval(&Runner::obs_args(h, &x, u, p, &[o.xl, o.yl]));
    Some([v[0], v[1]])
}

/// One innovation: measured minus predicted.
#[derive(Debug, Clone, Serialize)]
pub struct Innovation {
    pub t: f64,
    pub id: String,
    pub range_m: f64,
    pub bearing_rad: f64,
}

/// Innovation summary over runs.
#[derive(Debug, Clone, Serialize, Default)]
pub struct InnovationStats {
    pub observations: usize,
    pub landmarks: usize,
    pub range_rmse_m: f64,
    pub bearing_rmse_rad: f64,
    pub range_bias_m: f64,
    pub bearing_bias_rad: f64,
    /// The landmark with the largest RMS range innovation, and that RMS.
    pub worst_landmark: Option<(String, f64)>,
}

pub fn innovations(r: &Runner, p: &[f64], run: &Run, track: &Track) -> Vec<Innovation> {
    run.landmarks
        .iter()
        .filter_map(|o| {
            predict(r, p, run, track, o).map(|pr| Innovation {
                t: o.t,
                id: o.id.clone(),
                range_m: o.range - pr[0],
                bearing_rad: wrap(o.bearing - pr[1]),
            })
        })
        .collect()
}

pub fn stats(all: &[Innovation]) -> Option<InnovationStats> {
    if all.is_empty() {
        return None;
    }
    let n = all.len() as f64;
    let mut per: HashMap<&str, (f64, usize)> = HashMap::new();
    for i in all {
        let e = per.entry(&i.id).or_default();
        e.0 += i.range_m * i.range_m;
        e.1 += 1;
    }
    let worst = per
        .iter()
        .map(|(id, (s, k))| (id.to_string(), (s / *k as f64).sqrt()))
        .max_by(|a, b| a.1.total_cmp(&b.1));
    Some(InnovationStats {
        observations: all.len(),
        landmarks: per.len(),
        range_rmse_m: (all.iter().map(|i| i.range_m * i.range_m).sum::<f64>() / n).sqrt(),
        bearing_rmse_rad: (all
            .iter()
            .map(|i| i.bearing_rad * i.bearing_rad)
            .sum::<f64>()
            / n)
            .sqrt(),
        range_bias_m: all.iter().map(|i| i.range_m).sum::<f64>() / n,
        bearing_bias_rad: all.iter().map(|i| i.bearing_rad).sum::<f64>() / n,
        worst_landmark: worst,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_from_two_landmarks_is_exact() {
        let pose = [1.0, -2.0, 0.7];
        let marks = [("a", 4.0, 1.0), ("b", -1.0, 3.0), ("c", 0.0, -5.0)];
        let obs: Vec<LandmarkObs> = marks
            .iter()
            .map(|(id, x, y)| {
                let (dx, dy) = (x - pose[0], y - pose[1]);
                LandmarkObs {
                    t: 0.0,
                    id: id.to_string(),
                    xl: *x,
                    yl: *y,
                    range: dx.hypot(dy),
                    bearing: dy.atan2(dx) - pose[2],
                }
            })
            .collect();
        let got = pose_from_landmarks(&obs, 0.5).unwrap();
        for i in 0..3 {
            assert!((got[i] - pose[i]).abs() < 1e-12, "{got:?}");
        }
        assert!(pose_from_landmarks(&obs[..1], 0.5).is_none());
    }
}
