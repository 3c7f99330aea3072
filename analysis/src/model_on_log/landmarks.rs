//! Range-bearing observations of known landmarks (CONTRACT section 2): `OBS.csv`
//! with `t,id,range,bearing` (bearing relative to the robot heading) and `MAP.csv`
//! with `id,x,y`, or detections read from a bag; and the start pose they fix
//! through the model's own `landmark` observation (seed 001 eq. 6). Their
//! innovations along a track are [`crate::model_on_log::innovations`].
use crate::logs::log::{read_csv, wrap, LogError};
use crate::model_on_log::model::Runner;
use crate::model_on_log::run::{LandmarkObs, Run};
use kinegen_model::decl::ObservationRole::RangeBearing;
use std::collections::{BTreeSet, HashMap};
use std::path::Path;

/// Range and bearing noise (m, rad) when the spec's `landmark` observation
/// declares none.
pub const DEFAULT_SIGMA: [f64; 2] = [0.05, 0.02];

/// Landmark positions by id.
#[derive(Debug, Clone, Default)]
pub struct Map {
    /// The ids as the map spells them, in its order.
    pub ids: Vec<String>,
    /// Positions, in the order of `ids`.
    xy: Vec<[f64; 2]>,
    /// Where in `ids` a landmark is, by [`key`].
    index: HashMap<String, usize>,
    /// The file's line of the first landmark.
    pub first_line: usize,
}

/// The key an id is looked up by: an integral number in any spelling (`7`,
/// `07`, `7.0`: a table written by another tool turns integer ids into
/// floats) is that integer; any other id is its text.
fn key(id: &str) -> String {
    match id.parse::<f64>() {
        Ok(v) if v.fract() == 0.0 && v.abs() < 1e15 => format!("{}", v as i64),
        _ => id.to_string(),
    }
}

impl Map {
    /// Landmark `id`'s spelling in the map and its position, however a
    /// number is spelt.
    pub fn find(&self, id: &str) -> Option<(&str, [f64; 2])> {
        let &i = self.index.get(&key(id))?;
        Some((self.ids[i].as_str(), self.xy[i]))
    }

    /// The position of landmark `id`, one of [`Map::ids`].
    pub fn position(&self, id: &str) -> [f64; 2] {
        self.xy[self.index[&key(id)]]
    }
}

/// Read `MAP.csv` (`id,x,y`); ids are text and must be unique.
pub fn read_map(path: &Path) -> Result<Map, LogError> {
    let (h, mut rdr) = read_csv(path, "landmark map")?;
    let cols = h.require(&["id", "x", "y"])?;
    let (id_i, x_i, y_i) = (cols[0], cols[1], cols[2]);
    let mut map = Map {
        first_line: h.first_data_line,
        ..Map::default()
    };
    for (n, rec) in rdr.records().enumerate() {
        let (line, rec) = h.record(n, rec)?;
        let id = h.text(line, &rec, id_i)?.to_string();
        if id.is_empty() {
            return Err(h.err(Some(line), Some("id"), "empty landmark id"));
        }
        let xy = [h.number(line, &rec, x_i)?, h.number(line, &rec, y_i)?];
        if map.index.insert(key(&id), map.ids.len()).is_some() {
            return Err(h.err(
                Some(line),
                Some("id"),
                format!("landmark `{id}` is listed twice"),
            ));
        }
        map.xy.push(xy);
        map.ids.push(id);
    }
    if map.ids.is_empty() {
        return Err(h.err(None, None, "the map lists no landmarks"));
    }
    Ok(map)
}

/// Sightings whose id the map does not have, left out: a camera that reads
/// barcodes also reads other robots' and the odd misread one, which a
/// localisation ignores rather than stop at. Where they are and which ids.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Unmapped {
    pub count: usize,
    pub ids: BTreeSet<String>,
    /// Where the first was: `line N` of a CSV file, `message N` of a topic.
    pub first: String,
}

impl Unmapped {
    fn add(&mut self, id: &str, at: impl FnOnce() -> String) {
        if self.count == 0 {
            self.first = at();
        }
        self.count += 1;
        self.ids.insert(id.to_string());
    }

    /// The ids, a few of them, for a sentence.
    pub fn some_ids(&self) -> String {
        let mut v: Vec<String> = self.ids.iter().take(6).map(|i| format!("`{i}`")).collect();
        if self.ids.len() > 6 {
            v.push(format!("{} more", self.ids.len() - 6));
        }
        v.join(", ")
    }

    /// The error when no sighting at all is in the map (a map for another
    /// room, or ids written differently): then nothing is left to use.
    fn none_mapped(&self, source: &Path, map: &Map, map_path: &Path) -> LogError {
        let has: Vec<&str> = map.ids.iter().take(6).map(String::as_str).collect();
        LogError::new(
            source,
            None,
            Some("id"),
            format!(
                "no sighting's landmark is in the map: {} (first at {}) are not in the map {}, which has {}{}",
                self.some_ids(),
                self.first,
                map_path.display(),
                has.join(", "),
                if map.ids.len() > 6 { ", ..." } else { "" }
            ),
        )
    }
}

/// A sighting written twice (the same time, landmark, range and bearing): a
/// frame logged twice, which counted twice would make the filter trust that
/// frame double. Left out and counted.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Repeated {
    pub count: usize,
    /// Where the first was, as [`Unmapped::first`].
    pub first: String,
}

impl Repeated {
    fn add(&mut self, at: impl FnOnce() -> String) {
        if self.count == 0 {
            self.first = at();
        }
        self.count += 1;
    }
}

/// The sightings of one source that a localisation uses, and those it left out.
#[derive(Debug, Clone, Default)]
pub struct Sightings {
    pub obs: Vec<LandmarkObs>,
    pub unmapped: Unmapped,
    pub repeated: Repeated,
}

/// Whether `o` repeats a sighting of `same_time` (the sightings read so far
/// at its time) exactly.
fn repeats(same_time: &[LandmarkObs], o: &LandmarkObs) -> bool {
    same_time
        .iter()
        .any(|p| p.id == o.id && p.range == o.range && p.bearing == o.bearing)
}

/// The sightings of `out` at time `t`, which are its last ones (`out` is in time order).
fn at_time(out: &[LandmarkObs], t: f64) -> &[LandmarkObs] {
    let first = out.iter().rposition(|p| p.t != t).map_or(0, |k| k + 1);
    &out[first..]
}

/// Read `OBS.csv` (`t,id,range,bearing`): time non-decreasing (several landmarks
/// may be seen at one instant), range positive. Sightings of ids the map does
/// not have, and sightings written twice, are left out and counted; none in
/// the map is an error.
pub fn read_observations(path: &Path, map: &Map, map_path: &Path) -> Result<Sightings, LogError> {
    let (h, mut rdr) = read_csv(path, "landmark observations")?;
    let cols = h.require(&["t", "id", "range", "bearing"])?;
    let (t_i, id_i, range_i, bearing_i) = (cols[0], cols[1], cols[2], cols[3]);
    let mut out: Vec<LandmarkObs> = Vec::new();
    let mut unmapped = Unmapped::default();
    let mut repeated = Repeated::default();
    let mut last_t = f64::NEG_INFINITY;
    for (n, rec) in rdr.records().enumerate() {
        let (line, rec) = h.record(n, rec)?;
        let t = h.number(line, &rec, t_i)?;
        if t < last_t {
            return Err(h.err(
                Some(line),
                Some("t"),
                format!("time goes backwards: {t} follows {last_t}"),
            ));
        }
        last_t = t;
        let id = h.text(line, &rec, id_i)?.to_string();
        let Some((id, [xl, yl])) = map.find(&id).map(|(s, p)| (s.to_string(), p)) else {
            unmapped.add(&id, || format!("line {line}"));
            continue;
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
        if let Some(why) = not_radians(bearing) {
            return Err(h.err(Some(line), Some("bearing"), why));
        }
        let o = LandmarkObs {
            t,
            id: id.into(),
            xl,
            yl,
            range,
            bearing,
        };
        if repeats(at_time(&out, t), &o) {
            repeated.add(|| format!("line {line}"));
            continue;
        }
        out.push(o);
    }
    if out.is_empty() {
        if unmapped.count > 0 {
            return Err(unmapped.none_mapped(path, map, map_path));
        }
        return Err(h.err(None, None, "no observations"));
    }
    Ok(Sightings {
        obs: out,
        unmapped,
        repeated,
    })
}

/// Why `bearing` cannot be an angle in radians, if it cannot: beyond a full
/// turn either way (a bearing wrapped to (-pi, pi] or to [0, 2 pi) is
/// within it). A column in degrees whose values all lie within 2 pi is
/// caught by the spacing check ([`crate::model_on_log::sighting_units`]).
fn not_radians(bearing: f64) -> Option<String> {
    (bearing.abs() > std::f64::consts::TAU).then(|| {
        format!("bearing {bearing} is beyond a full turn (2 pi): bearings are in radians (is it in degrees?)")
    })
}

/// Range-bearing observations from a bag's landmark topic (see
/// [`crate::logs::bag::LandmarkSource`]) whose ids the map has, ordered by time,
/// and those it has not or that repeat one (as [`read_observations`]).
pub fn from_detections(
    bag: &Path,
    found: &[crate::logs::bag::Detection],
    map: &Map,
    map_path: &Path,
) -> Result<Sightings, LogError> {
    let mut out: Vec<LandmarkObs> = Vec::with_capacity(found.len());
    let mut unmapped = Unmapped::default();
    let mut repeated = Repeated::default();
    let mut found: Vec<&crate::logs::bag::Detection> = found.iter().collect();
    found.sort_by(|a, b| a.t.total_cmp(&b.t));
    for d in found {
        if let Some(why) = not_radians(d.bearing) {
            return Err(LogError::new(
                bag,
                None,
                None,
                format!(
                    "topic `{}` message {} (counting from 0): {why}",
                    d.topic, d.index
                ),
            ));
        }
        let Some((id, [xl, yl])) = map.find(&d.id).map(|(s, p)| (s.to_string(), p)) else {
            unmapped.add(&d.id, || {
                format!("topic `{}` message {} (counting from 0)", d.topic, d.index)
            });
            continue;
        };
        let o = LandmarkObs {
            t: d.t,
            id: id.into(),
            xl,
            yl,
            range: d.range,
            bearing: d.bearing,
        };
        if repeats(at_time(&out, d.t), &o) {
            repeated.add(|| format!("topic `{}` message {} (counting from 0)", d.topic, d.index));
            continue;
        }
        out.push(o);
    }
    if out.is_empty() && unmapped.count > 0 {
        return Err(unmapped.none_mapped(bag, map, map_path));
    }
    Ok(Sightings {
        obs: out,
        unmapped,
        repeated,
    })
}

/// A start pose placed by landmark sightings.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedStart {
    pub pose: [f64; 3],
    /// d pose / d parameters, 3 x P row-major.
    pub d_dp: Vec<f64>,
    /// The pose's covariance: the inverse information of the sightings,
    /// scaled up by their residuals where those exceed the spec's sigmas
    /// (chi-square per degree of freedom over 1).
    pub cov: [[f64; 3]; 3],
}

/// The start pose that explains the range-bearing observations of the start
/// window through the model's own `landmark` observation (a sensor mounted off
/// the body origin included), by Gauss-Newton from `guess` (the closed-form
/// pose of a sensor at the origin, [`crate::model_on_log::run::pose_from_landmarks`]); with its
/// derivative with respect to the parameters (3 x P, row-major), from the
/// implicit function theorem: d x0 / d p = -(Hx' W Hx)^-1 Hx' W Hp.
/// None when the model has no such observation or too few are seen.
pub fn start_from_landmarks(
    r: &Runner,
    p: &[f64],
    run: &Run,
    guess: [f64; 3],
) -> Option<PlacedStart> {
    let seen = run.start_observations()?;
    let at_rest: Vec<(&LandmarkObs, [f64; 3], &[f64])> = seen
        .iter()
        .map(|o| (*o, [0.0; 3], run.u.first().unwrap_or(&[])))
        .collect();
    solve_start(r, p, &at_rest, guess)
}

/// Longest stretch of a run whose odometry places a moving robot's first
/// sightings: a few seconds of drift are centimetres.
pub const MOVING_START_S: f64 = 20.0;
/// Sightings that fix a moving robot's start (of two landmarks at least).
const MOVING_START_SIGHTINGS: usize = 4;

/// The first sightings of a robot that moves from its first row and sees no
/// two landmarks at once there (a velocity-commanded robot's log without
/// motion capture): up to [`MOVING_START_SIGHTINGS`] of two landmarks or more
/// within [`MOVING_START_S`] of the first of them. That stretch starts at the
/// run's first sighting where it has enough, or else at the first sighting
/// that begins one: a robot that sees nothing for its first minute is placed
/// by what it sees next, through its odometry from the start, rather than
/// left at the map's origin. None when no stretch has enough.
pub fn first_sightings(run: &Run) -> Option<Vec<&LandmarkObs>> {
    let mut inside: Vec<&LandmarkObs> = run.landmarks.iter().filter(|o| o.t >= run.t[0]).collect();
    inside.sort_by(|a, b| a.t.total_cmp(&b.t));
    (0..inside.len()).find_map(|k| enough_within(&inside[k..]))
}

/// The leading sightings of `seen` (in time order) that fix a start, all
/// within [`MOVING_START_S`] of the first; None where they do not suffice.
fn enough_within<'a>(seen: &[&'a LandmarkObs]) -> Option<Vec<&'a LandmarkObs>> {
    let t_end = seen.first()?.t + MOVING_START_S;
    let mut ids: Vec<&str> = Vec::new();
    for (k, o) in seen.iter().take_while(|o| o.t <= t_end).enumerate() {
        if !ids.contains(&&*o.id) {
            ids.push(&o.id);
        }
        if ids.len() >= 2 && k + 1 >= MOVING_START_SIGHTINGS {
            return Some(seen[..=k].to_vec());
        }
    }
    None
}

/// The start pose from sightings `seen` of a robot that moved between them:
/// `moved(o)`, its pose at sighting `o` in the start's frame (the model's
/// odometry from the start), places each; then [`solve_start`] as at rest.
/// The derivative in the parameters leaves out the odometry's (over seconds
/// it moves the start by a fraction of what the observation's parameters do).
pub fn start_from_moving_sightings(
    r: &Runner,
    p: &[f64],
    run: &Run,
    seen: &[&LandmarkObs],
    moved: impl Fn(&LandmarkObs) -> [f64; 3],
) -> Option<PlacedStart> {
    let guess = crate::model_on_log::run::pose_from_sightings(seen, &moved)?;
    let placed: Vec<(&LandmarkObs, [f64; 3], &[f64])> = seen
        .iter()
        .map(|o| {
            let j = run.locate(o.t).0.min(run.steps() - 1);
            (*o, moved(o), &run.u[j])
        })
        .collect();
    solve_start(r, p, &placed, guess)
}

/// The pose `s` from which sightings, each seen from `s` moved by its
/// relative pose (and with its inputs), fit the model's `landmark`
/// observation best: Gauss-Newton from `guess`, with d s / d p by the
/// implicit function theorem (see [`start_from_landmarks`]).
fn solve_start(
    r: &Runner,
    p: &[f64],
    seen: &[(&LandmarkObs, [f64; 3], &[f64])],
    guess: [f64; 3],
) -> Option<PlacedStart> {
    use nalgebra::{DMatrix, Matrix3, Vector3};
    let h = r.ir.observation_kernels(RangeBearing).map(|o| o.value)?;
    let hx = r.ir.observation_kernels(RangeBearing).map(|o| o.jac_x)?;
    let hp =
        r.ir.observation_kernels(RangeBearing)
            .and_then(|o| o.jac_p)?;
    let sigma = sigma(r);
    let w = [1.0 / (sigma[0] * sigma[0]), 1.0 / (sigma[1] * sigma[1])];
    let np = p.len();
    let mut x = guess;
    // normal equations of the weighted observations at x: (J' W J, J' W r, J' W Hp,
    // r' W r), J = Hx G with G = d(x moved by m)/dx
    let normal = |x: &[f64; 3], with_p: bool| {
        let (mut a, mut b) = (Matrix3::<f64>::zeros(), Vector3::<f64>::zeros());
        let mut chi2 = 0.0;
        let mut c = DMatrix::zeros(3, if with_p { np } else { 0 });
        let (s, co) = x[2].sin_cos();
        for (o, m, u) in seen {
            let at = [
                x[0] + co * m[0] - s * m[1],
                x[1] + s * m[0] + co * m[1],
                x[2] + m[2],
            ];
            let lm = [o.xl, o.yl];
            let pred = r.eval(h, &Runner::obs_args(h, &at, u, p, &lm));
            let res = [o.range - pred[0], wrap(o.bearing - pred[1])];
            let jx = r.eval(hx, &Runner::obs_args(hx, &at, u, p, &lm));
            let (dx_dth, dy_dth) = (-s * m[0] - co * m[1], co * m[0] - s * m[1]);
            let j = |k: usize, i: usize| match i {
                0 => jx[k * 3],
                1 => jx[k * 3 + 1],
                _ => jx[k * 3] * dx_dth + jx[k * 3 + 1] * dy_dth + jx[k * 3 + 2],
            };
            let jp = with_p.then(|| r.eval(hp, &Runner::obs_args(hp, &at, u, p, &lm)));
            chi2 += w[0] * res[0] * res[0] + w[1] * res[1] * res[1];
            for k in 0..2 {
                for i in 0..3 {
                    b[i] += j(k, i) * w[k] * res[k];
                    for jj in 0..3 {
                        a[(i, jj)] += j(k, i) * w[k] * j(k, jj);
                    }
                    if let Some(jp) = &jp {
                        for q in 0..np {
                            c[(i, q)] += j(k, i) * w[k] * jp[k * np + q];
                        }
                    }
                }
            }
        }
        (a, b, c, chi2)
    };
    for _ in 0..20 {
        let (a, b, _, _) = normal(&x, false);
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
    let (a, _, c, chi2) = normal(&x, true);
    let a_inv = a.try_inverse()?;
    let d = -(a_inv * c);
    // row-major 3 x P, as body_start gives it
    let d_dp: Vec<f64> = (0..3)
        .flat_map(|i| (0..np).map(move |j| (i, j)))
        .map(|(i, j)| d[(i, j)])
        .collect();
    let dof = (2 * seen.len()).saturating_sub(3).max(1) as f64;
    let cov = a_inv * (chi2 / dof).max(1.0);
    Some(PlacedStart {
        pose: x,
        d_dp,
        cov: [0, 1, 2].map(|i| [0, 1, 2].map(|j| cov[(i, j)])),
    })
}

/// Range and bearing noise of the model's `landmark` observation (or the
/// defaults when it declares none).
pub fn sigma(r: &Runner) -> [f64; 2] {
    r.obs_sigma(RangeBearing)
        .filter(|_| declares_sigma(r))
        .map_or(DEFAULT_SIGMA, |s| [s[0], s[1]])
}

/// Whether the model's `landmark` observation declares its sigmas (the
/// spec leaves them at 0 where it gives none, and refuses a 0 it is given).
pub fn declares_sigma(r: &Runner) -> bool {
    r.obs_sigma(RangeBearing)
        .is_some_and(|s| s.len() == 2 && s.iter().all(|v| *v > 0.0))
}
