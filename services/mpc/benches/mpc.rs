//! MPC solve time (linearise + condense + solve) at P = 10, 20, 30 with the default move
//! blocking (5 moves). First a table from the library's closed loop (a plant tracking a
//! moving, turning target): p50 / p99 / max per step with the unconstrained-first path on
//! and off, the share of steps it solved, and the p50 of the steps clarabel solved. Then
//! criterion's mean on inputs that keep bounds active (every step goes to clarabel), and on
//! the same inputs with returns on the way (every step solves the safety layer's QP).
//!
//! `cargo bench -p mpc --bench mpc`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use mpc::{Keepout, Mpc, MpcConfig, MpcInput, MpcStatus, MpcTarget};
use nalgebra::{UnitQuaternion, Vector3, Vector6};
use sim_plant::model::Vehicle;
use sim_plant::VehicleParams;

fn inputs() -> Vec<MpcInput> {
    (0..64)
        .map(|k| {
            let a = f64::from(k) * 0.1;
            MpcInput {
                attitude: UnitQuaternion::from_euler_angles(0.05 * a.sin(), 0.03 * a.cos(), a),
                nu: Vector6::new(1.2 + 0.2 * a.sin(), 0.1 * a.cos(), 0.05, 0.01, -0.02, 0.05),
                target: MpcTarget {
                    position_m: Vector3::new(3.0 + a.sin(), 2.0 * a.cos(), 0.5),
                    velocity_mps: Vector3::new(1.0, 0.2, 0.0),
                    yaw_rel_rad: 0.3 * a.sin(),
                },
                keepout: Keepout::default(),
            }
        })
        .collect()
}

/// p50 / p99 of a sorted sample.
fn pct(sorted: &[f64], p: f64) -> f64 {
    if sorted.is_empty() {
        return f64::NAN;
    }
    #[allow(
        clippy::cast_precision_loss,
        clippy::cast_possible_truncation,
        clippy::cast_sign_loss
    )]
    let i = ((sorted.len() - 1) as f64 * p).round() as usize;
    sorted[i]
}

/// The closed loop of `mpc::closed_loop` (a plant tracking a moving, turning target, 5 cm
/// noise), 120 s = 1200 control steps: solve time of every step, and of the steps clarabel
/// solved, with and without the unconstrained-first path.
fn closed_loop_table() {
    println!("closed loop, 1200 steps: solve time per step, us");
    println!(
        "{:>3} {:>13} {:>7} {:>7} {:>7} {:>10} {:>13}",
        "P", "uncon. first", "p50", "p99", "max", "shortcut", "clarabel p50"
    );
    for horizon in [10usize, 20, 30] {
        for first in [true, false] {
            let cfg = MpcConfig {
                horizon,
                unconstrained_first: first,
                ..MpcConfig::default()
            };
            let (mut all, mut qp) = (Vec::new(), Vec::new());
            let mut shortcut = 0usize;
            mpc::closed_loop::run(&cfg, 120.0, 0.05, |s| {
                let us = s.solve.as_secs_f64() * 1e6;
                all.push(us);
                match s.result {
                    Ok(o) if o.status == MpcStatus::Unconstrained => shortcut += 1,
                    _ => qp.push(us),
                }
            })
            .unwrap_or_else(|e| unreachable!("{e}"));
            all.sort_by(f64::total_cmp);
            qp.sort_by(f64::total_cmp);
            println!(
                "{horizon:>3} {:>13} {:>7.0} {:>7.0} {:>7.0} {:>9.0}% {:>13.0}",
                if first { "on" } else { "off" },
                pct(&all, 0.5),
                pct(&all, 0.99),
                pct(&all, 1.0),
                100.0 * shortcut as f64 / all.len() as f64,
                pct(&qp, 0.5)
            );
        }
    }
}

fn bench_mpc(c: &mut Criterion) {
    closed_loop_table();
    let vehicle = Vehicle::new(&VehicleParams::default()).unwrap_or_else(|e| unreachable!("{e}"));
    let inputs = inputs();
    bench_steps(c, "mpc_step", &vehicle, &inputs);
    // The safety layer's QP: a return 2.5 m ahead on the reference, eight in all and the
    // parent, so that every step solves the guarded QP (45 half-spaces with their slacks).
    let guarded: Vec<MpcInput> = inputs
        .iter()
        .map(|i| {
            let mut keepout = Keepout::default();
            for j in 0..8 {
                keepout.push([2.5 + 0.3 * f64::from(j), -3.0 + f64::from(j), 0.0]);
            }
            keepout.parent = Some(([6.0, 4.0, 0.0], [1.0, 0.0, 0.0]));
            MpcInput { keepout, ..*i }
        })
        .collect();
    bench_steps(c, "mpc_step_guarded", &vehicle, &guarded);
}

/// Criterion's time of a step on `inputs` in turn, at P = 10, 20, 30.
fn bench_steps(c: &mut Criterion, name: &str, vehicle: &Vehicle, inputs: &[MpcInput]) {
    let mut group = c.benchmark_group(name);
    for horizon in [10usize, 20, 30] {
        let cfg = MpcConfig {
            horizon,
            ..MpcConfig::default()
        };
        let mut mpc = Mpc::new(&cfg, vehicle).unwrap_or_else(|e| unreachable!("{e}"));
        let mut k = 0usize;
        group.bench_with_input(BenchmarkId::from_parameter(horizon), &horizon, |b, _| {
            b.iter(|| {
                k = (k + 1) % inputs.len();
                let r = mpc.step(black_box(&inputs[k]));
                black_box(r.map(|o| o.tau).unwrap_or_else(|_| mpc.fallback()))
            });
        });
    }
    group.finish();
}

criterion_group!(benches, bench_mpc);
criterion_main!(benches);
