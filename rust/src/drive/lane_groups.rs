//! The vector lanes' side of the driver: lane groups run by the SoA RK4 and Dormand-Prince
//! drivers (`lanes/`), compiled per instruction set (`pulp`), what `auto` hands over to the
//! implicit method, and the fixed-step groups the vector drivers do not take.

use std::marker::PhantomData;
use std::sync::atomic::AtomicBool;

use crate::integrate::method::Method;
use crate::integrate::model_rhs::ModelRhs;
use crate::integrate::rodas4::Rodas4;
use crate::integrate::stepper::Held;
use crate::integrate::task::{LaneEnd, Observer, Resume, Task};
use crate::lanes::dopri5::{run_dopri5_lanes, Handoff};
use crate::lanes::rk4::run_rk4_lanes;
use crate::lanes::{simd_arch, LaneExp, LanesRhs, PlainLanes};

use super::{drive_group, group_options, run_group, switching, Renumbered};

/// The vector drivers' part of a lane group run (see [`PlainGroups`]): every task's end, and the
/// runs `method="auto"` handed over to the implicit method; or `Fallback` when the vector drivers
/// do not run these tasks (another shape, or Rodas4).
enum LaneRun {
    Fallback,
    Ran {
        ends: Vec<Option<(LaneEnd, Vec<f64>)>>,
        handoffs: Vec<Handoff>,
    },
}

/// The vector lane drivers over f64 tasks with `N` nodes and `D` state components (`EXTRAS`:
/// lag states beside the plain ones, see [`Model::lane_lags`](crate::model::Model::lane_lags)),
/// as one operation for `pulp` to compile once per instruction set: its `with_simd` runs inside
/// a function with that set's features enabled, and everything it calls is inlined into it
/// (closures are not: the call through `FnOnce` stays out of line, compiled for the baseline).
/// Only the two SoA drivers are in it; the hand-overs to the implicit method have their own
/// dispatch (`HandOvers`), and the lane-by-lane fallback (`run_fixed`) is compiled once, for the
/// baseline (build time; the bits are the same either way).
struct PlainGroups<'t, 'a, O, E, const N: usize, const D: usize, const EXTRAS: bool, const L: usize> {
    tasks: &'t [Task<'a>],
    method: &'t Method,
    observer: &'t mut O,
    cancel: &'t AtomicBool,
    _exp: PhantomData<E>,
}

impl<O: Observer, E: LaneExp, const N: usize, const D: usize, const EXTRAS: bool, const L: usize> pulp::WithSimd
    for PlainGroups<'_, '_, O, E, N, D, EXTRAS, L>
{
    type Output = Option<LaneRun>;

    #[inline(always)]
    fn with_simd<Sd: pulp::Simd>(self, _simd: Sd) -> Option<LaneRun> {
        let shape = self.tasks[0].model.shape();
        if !self
            .tasks
            .iter()
            .all(|t| PlainLanes::<N, L, E>::accepts(t.model) && t.model.shape() == shape && t.model.layout.dim == D)
        {
            return Some(LaneRun::Fallback);
        }
        // the state stored component by component, lanes refilled from the queue
        Some(match *self.method {
            Method::Rk4 { dt } => {
                let ends = run_rk4_lanes::<O, E, N, D, EXTRAS, L>(self.tasks, dt, self.observer, self.cancel)?;
                LaneRun::Ran {
                    ends: ends.into_iter().map(Some).collect(),
                    handoffs: Vec::new(),
                }
            }
            Method::Dopri5 { rtol, atol, first_step } | Method::Auto { rtol, atol, first_step } => {
                let auto = matches!(self.method, Method::Auto { .. });
                let mut handoffs = Vec::new();
                let ends = run_dopri5_lanes::<O, E, N, D, EXTRAS, L>(
                    self.tasks,
                    rtol,
                    atol,
                    first_step,
                    self.observer,
                    self.cancel,
                    auto,
                    &mut handoffs,
                )?;
                LaneRun::Ran { ends, handoffs }
            }
            Method::Rodas4 { .. } => LaneRun::Fallback,
        })
    }
}

/// The runs `method="auto"` handed over to the implicit method (`handoffs`, from the vector
/// drivers), `L` at a time as lane-interleaved scalar code, each one's end into `ends`; one
/// operation for `pulp` so that it can be compiled for an instruction set (its calls inlined).
struct HandOvers<'t, 'a, O, E, const N: usize, const D: usize, const EXTRAS: bool, const L: usize> {
    tasks: &'t [Task<'a>],
    _exp: PhantomData<E>,
    handoffs: &'t [Handoff],
    method: &'t Method,
    observer: &'t mut O,
    cancel: &'t AtomicBool,
    ends: &'t mut [Option<(LaneEnd, Vec<f64>)>],
}

impl<O: Observer, E: LaneExp, const N: usize, const D: usize, const EXTRAS: bool, const L: usize> pulp::WithSimd
    for HandOvers<'_, '_, O, E, N, D, EXTRAS, L>
{
    type Output = Option<()>;

    #[inline(always)]
    fn with_simd<Sd: pulp::Simd>(self, _simd: Sd) -> Option<()> {
        if self.handoffs.is_empty() {
            return Some(()); // any method: only auto hands runs over
        }
        let Method::Auto { rtol, atol, first_step } = *self.method else {
            unreachable!("only auto hands runs over")
        };
        for group in self.handoffs.chunks(L) {
            let chunk: Vec<Task> = group
                .iter()
                .map(|h| Task {
                    t_start: h.t,
                    y0: &h.y,
                    ..self.tasks[h.task]
                })
                .collect();
            let resume: Vec<Resume> = group.iter().map(|h| h.resume).collect();
            let index: Vec<usize> = group.iter().map(|h| h.task).collect();
            let mut done = Vec::with_capacity(group.len());
            let opts = group_options(&chunk, rtol, atol, first_step, &Held::default());
            let st = switching::<[f64; D], D, L>(opts, [0.0; D], Some(&resume));
            let observer = &mut Renumbered {
                inner: &mut *self.observer,
                index: &index,
            };
            if EXTRAS {
                // lag states run lane by lane
                let rhs = ModelRhs::<f64, N, EXTRAS, L>::for_tasks;
                drive_group(
                    &chunk,
                    0,
                    0.0,
                    st,
                    [0.0; D],
                    rhs,
                    observer,
                    self.cancel,
                    &mut done,
                    Some(&resume),
                )?;
            } else {
                // the stages of both methods as vectors where half the lanes are busy
                let rhs = LanesRhs::<E, N, D, L, EXTRAS>::for_tasks;
                drive_group(
                    &chunk,
                    0,
                    0.0,
                    st,
                    [0.0; D],
                    rhs,
                    observer,
                    self.cancel,
                    &mut done,
                    Some(&resume),
                )?;
            }
            for (h, end) in group.iter().zip(done) {
                self.ends[h.task] = Some(end);
            }
        }
        Some(())
    }
}

/// Run the hand-overs compiled for AVX2 (+FMA) where the lanes run on AVX2, else for the
/// baseline: two copies of the implicit method's code per shape, not one per instruction set
/// (build time). The bits are the same either way (no fused multiply-add is contracted).
#[inline(always)]
fn hand_over_dispatch<Op: pulp::WithSimd>(op: Op) -> Op::Output {
    match simd_arch() {
        #[cfg(target_arch = "x86_64")]
        pulp::Arch::V3(v3) => pulp::Simd::vectorize(v3, op),
        _ => op.with_simd(pulp::Scalar::new()),
    }
}

/// Rodas4 over plain models (`tasks`), `L` at a time, the stages as vectors where at least half
/// the lanes are busy ([`LanesRhs`]): one operation for `pulp`, compiled for AVX2 as
/// [`HandOvers`].
struct Rodas4Groups<'t, 'a, O, E, const N: usize, const D: usize, const L: usize> {
    tasks: &'t [Task<'a>],
    method: &'t Method,
    observer: &'t mut O,
    cancel: &'t AtomicBool,
    out: &'t mut Vec<(LaneEnd, Vec<f64>)>,
    _exp: PhantomData<E>,
}

impl<O: Observer, E: LaneExp, const N: usize, const D: usize, const L: usize> pulp::WithSimd
    for Rodas4Groups<'_, '_, O, E, N, D, L>
{
    type Output = Option<()>;

    #[inline(always)]
    fn with_simd<Sd: pulp::Simd>(self, _simd: Sd) -> Option<()> {
        let Method::Rodas4 { rtol, atol, first_step } = *self.method else {
            unreachable!("Rodas4 groups")
        };
        for (c, chunk) in self.tasks.chunks(L).enumerate() {
            let st: Rodas4<[f64; D], L, D> =
                Rodas4::new(group_options(chunk, rtol, atol, first_step, &Held::default()), [0.0; D]);
            let rhs = LanesRhs::<E, N, D, L>::for_tasks;
            drive_group(
                chunk,
                c * L,
                0.0,
                st,
                [0.0; D],
                rhs,
                &mut *self.observer,
                self.cancel,
                &mut *self.out,
                None,
            )?;
        }
        Some(())
    }
}

/// Run `tasks` of one fixed-size state layout (`N` nodes, `D` components, `EXTRAS`: lag states)
/// into `out`: on the vector lanes where they run there (`PlainGroups`, under `pulp`'s dispatch),
/// the runs that turned stiff then with the implicit method, `L` at a time; else `L` at a time
/// as lane-interleaved scalar code. `None` if cancelled.
pub(super) fn run_fixed<O: Observer, E: LaneExp, const N: usize, const D: usize, const EXTRAS: bool, const L: usize>(
    tasks: &[Task],
    method: &Method,
    observer: &mut O,
    cancel: &AtomicBool,
    out: &mut Vec<(LaneEnd, Vec<f64>)>,
) -> Option<()> {
    // a vector step costs about what L/2 to L/3 lanes cost one by one, busy or not (measured:
    // three runs of a lag model on 8 lanes 1.07-1.36x their time one by one, nine 0.52x), so a
    // group that fills less than half its lanes runs lane by lane (the same bits either way)
    let run = if 2 * tasks.len() >= L {
        let groups = PlainGroups::<O, E, N, D, EXTRAS, L> {
            tasks,
            method,
            observer: &mut *observer,
            cancel,
            _exp: PhantomData,
        };
        simd_arch().dispatch(groups)?
    } else {
        LaneRun::Fallback
    };
    match run {
        LaneRun::Ran { mut ends, handoffs } => {
            // lanes that turned stiff go on with the implicit method, L at a time: for the plain
            // shapes (no lag states: the sweeps'), compiled for AVX2 (+FMA) as well as for the
            // baseline (RESULTS §22); with lag states (the diagnosis's) once, for the baseline
            let op = HandOvers::<O, E, N, D, EXTRAS, L> {
                tasks,
                _exp: PhantomData,
                handoffs: &handoffs,
                method,
                observer: &mut *observer,
                cancel,
                ends: &mut ends,
            };
            if !EXTRAS {
                hand_over_dispatch(op)?;
            } else {
                pulp::WithSimd::with_simd(op, pulp::Scalar::new())?;
            }
            out.extend(ends.into_iter().map(|o| o.expect("every task ends")));
        }
        LaneRun::Fallback => {
            if !EXTRAS && matches!(method, Method::Rodas4 { .. }) {
                // its stages as vectors, compiled for AVX2 as the hand-overs
                hand_over_dispatch(Rodas4Groups::<O, E, N, D, L> {
                    tasks,
                    method,
                    observer,
                    cancel,
                    out,
                    _exp: PhantomData,
                })?;
            } else {
                for (c, chunk) in tasks.chunks(L).enumerate() {
                    run_group::<[f64; D], O, _, D, L>(
                        chunk,
                        c * L,
                        method,
                        &Held::default(),
                        [0.0; D],
                        ModelRhs::<f64, N, EXTRAS, L>::for_tasks,
                        observer,
                        cancel,
                        out,
                        None,
                    )?;
                }
            }
        }
    }
    Some(())
}
