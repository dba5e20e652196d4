//! Building batch points from plain tables (one row per point), as the Python sweep and the fits
//! hand them over: parameters in `PARAM_NAMES` order, effects in `EFFECT_NAMES` order, and the
//! input as one waveform family with its fields per point. A row that does not make a valid
//! point gives the reason instead (the point is then flagged `Invalid`, the others run).

use crate::physics::effects::{Effects, EFFECT_NAMES};
use crate::physics::params::{Params, PARAM_NAMES};
use crate::physics::waveform::PiecewiseLinear;

use super::{PointSpec, Train};
use crate::error::InputError;

/// The input of every point of a batch: one family, its fields per point.
#[derive(Clone, Debug, PartialEq)]
pub enum WaveFamily {
    /// fields [amplitude V, rise s, fall s, delay s]
    Triangle,
    /// fields [amplitude V, frequency Hz, cycles, rise s, forward (1/0), delay s]
    Sawtooth,
    /// one sampled input (t [s], V [V]) shared by all points; field [amplitude scale]
    Sampled { t: Vec<f64>, v: Vec<f64> },
}

impl WaveFamily {
    /// Parse a family name; `sampled` needs the shared samples.
    pub fn new(kind: &str, sampled: Option<(Vec<f64>, Vec<f64>)>) -> Result<Self, InputError> {
        match (kind, sampled) {
            ("triangle", _) => Ok(WaveFamily::Triangle),
            ("sawtooth", _) => Ok(WaveFamily::Sawtooth),
            ("sampled", Some((t, v))) => Ok(WaveFamily::Sampled { t, v }),
            ("sampled", None) => Err("a sampled waveform needs its samples (t, V)".into()),
            (other, _) => Err(crate::input!(
                "waveform kind must be 'triangle', 'sawtooth' or 'sampled', got '{other}'"
            )),
        }
    }

    /// Names of the per-point fields, in column order.
    pub fn fields(&self) -> &'static [&'static str] {
        match self {
            WaveFamily::Triangle => &["amplitude", "rise", "fall", "delay"],
            WaveFamily::Sawtooth => &["amplitude", "frequency", "cycles", "rise", "forward", "delay"],
            WaveFamily::Sampled { .. } => &["amplitude"],
        }
    }

    /// The point's input and its drive cycles (a sawtooth train's).
    pub fn build(&self, row: &[f64]) -> Result<(PiecewiseLinear, Option<Train>), InputError> {
        match self {
            WaveFamily::Triangle => {
                let [amplitude, rise, fall, delay] = row.try_into().map_err(|_| "row size")?;
                Ok((PiecewiseLinear::triangle(amplitude, rise, fall, delay)?, None))
            }
            WaveFamily::Sawtooth => {
                let [amplitude, frequency, cycles, rise, forward, delay] = row.try_into().map_err(|_| "row size")?;
                if !(cycles >= 1.0 && cycles.fract() == 0.0) {
                    return Err(crate::input!(
                        "parameter 'cycles' must be a positive integer, got {cycles}"
                    ));
                }
                let c = cycles as usize;
                let w = PiecewiseLinear::sawtooth(amplitude, frequency, c, rise, forward != 0.0, delay)?;
                Ok((w, Some(Train::new(frequency, c, delay))))
            }
            WaveFamily::Sampled { t, v } => {
                let scale = row[0];
                Ok((
                    PiecewiseLinear::new(t.clone(), v.iter().map(|x| x * scale).collect())?,
                    None,
                ))
            }
        }
    }
}

/// A point's Table 1 parameters and effects from its rows (`params` in `PARAM_NAMES` order, NaN
/// normal_force = derived from the masses; `effects` in `EFFECT_NAMES` order), and whether the
/// normal force was derived.
pub fn row_point(params: &[f64], effects: &[f64]) -> Result<(Params, Effects, bool), InputError> {
    let pairs: Vec<(&str, f64)> = PARAM_NAMES
        .iter()
        .copied()
        .zip(params.iter().copied())
        .filter(|(name, v)| !(*name == "normal_force" && v.is_nan()))
        .collect();
    let epairs: Vec<(&str, f64)> = EFFECT_NAMES.iter().copied().zip(effects.iter().copied()).collect();
    Ok((
        Params::from_pairs(&pairs)?,
        Effects::from_pairs(&epairs)?,
        pairs.len() < PARAM_NAMES.len(),
    ))
}

/// Per-point tables, row-major. `params` rows may hold NaN for `normal_force`: derived from the
/// masses. `t_ends`, `t_starts`, `states` (rows of `state_dim`) are optional per-point columns.
pub struct PointTables<'a> {
    pub params: &'a [f64],
    pub effects: &'a [f64],
    pub waves: &'a [f64],
    pub family: &'a WaveFamily,
    pub t_ends: Option<&'a [f64]>,
    pub t_starts: Option<&'a [f64]>,
    pub states: Option<(&'a [f64], usize)>,
}

impl PointTables<'_> {
    /// Number of points, after checking that every table has one row per point.
    pub fn len(&self) -> Result<usize, InputError> {
        let (np, ne, nw) = (PARAM_NAMES.len(), EFFECT_NAMES.len(), self.family.fields().len());
        let n = self.params.len() / np;
        let rows_ok = self.params.len() == n * np
            && self.effects.len() == n * ne
            && self.waves.len() == n * nw
            && self.t_ends.is_none_or(|t| t.len() == n)
            && self.t_starts.is_none_or(|t| t.len() == n)
            && self.states.is_none_or(|(s, d)| s.len() == n * d);
        if !rows_ok {
            return Err(crate::input!(
                "batch tables must have one row per point ({n}): parameters ({n}, {np}), effects ({n}, {ne}), \
                 waveform fields ({n}, {nw}: {}), and one t_end / t_start / state row per point when given",
                self.family.fields().join(", ")
            ));
        }
        Ok(n)
    }

    pub fn is_empty(&self) -> bool {
        self.params.is_empty()
    }

    /// Point `i`, or why its row is not a valid point.
    pub fn point(&self, i: usize) -> Result<PointSpec, InputError> {
        let (np, ne, nw) = (PARAM_NAMES.len(), EFFECT_NAMES.len(), self.family.fields().len());
        let (params, effects, derived) =
            row_point(&self.params[i * np..(i + 1) * np], &self.effects[i * ne..(i + 1) * ne])?;
        let (wave, train) = self.family.build(&self.waves[i * nw..(i + 1) * nw])?;
        let mut spec = PointSpec::new(params, effects, wave, train);
        spec.t_end = self.t_ends.map(|t| t[i]);
        spec.t_start = self.t_starts.map_or(0.0, |t| t[i]);
        spec.y0 = self.states.map(|(s, d)| s[i * d..(i + 1) * d].to_vec());
        spec.normal_force_derived = derived;
        Ok(spec)
    }

    /// Every point (or the reason it is invalid), in order.
    pub fn points(&self) -> Result<Vec<Result<PointSpec, InputError>>, String> {
        let n = self.len()?;
        Ok((0..n).map(|i| self.point(i)).collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rows_build_points_and_bad_rows_say_why() {
        let mut p = vec![f64::NAN; 2 * PARAM_NAMES.len()];
        for (j, name) in PARAM_NAMES.iter().enumerate() {
            if *name != "normal_force" {
                let v = Params::paper().get(name).unwrap();
                p[j] = v;
                p[PARAM_NAMES.len() + j] = v;
            }
        }
        p[PARAM_NAMES.len() + 1] = -1.0; // m2 of the second point
        let e = vec![0.0; 2 * EFFECT_NAMES.len()];
        let fam = WaveFamily::new("sawtooth", None).unwrap();
        let w = [60.0, 100.0, 2.0, 0.5e-3, 1.0, 0.0, 60.0, 100.0, 2.0, 0.5e-3, 0.0, 0.0];
        let tables = PointTables {
            params: &p,
            effects: &e,
            waves: &w,
            family: &fam,
            t_ends: None,
            t_starts: None,
            states: None,
        };
        let pts = tables.points().unwrap();
        let first = pts[0].as_ref().unwrap();
        assert_eq!(first.train, Some(Train::new(100.0, 2, 0.0)));
        assert_eq!(first.params, Params::paper());
        assert!(pts[1].as_ref().unwrap_err().contains("'m2'"));
        let short = PointTables {
            waves: &w[..6],
            ..tables
        };
        assert!(short.len().unwrap_err().contains("one row per point"));
    }
}
