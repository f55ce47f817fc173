//! MPC solve time (linearise + condense + clarabel) at P = 10, 20, 30 with the default
//! move blocking (5 moves), on a moving, turning target with the state changing each call.
//! Criterion reports the mean; before it, a plain loop prints p50 / p99 / max over 2000 calls
//! (the target is p99 < 1.5 ms at P = 20).
//!
//! `cargo bench -p mpc --bench mpc`

use std::hint::black_box;
use std::time::Instant;

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use mpc::{Mpc, MpcConfig, MpcInput, MpcTarget};
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
            }
        })
        .collect()
}

fn bench_mpc(c: &mut Criterion) {
    let vehicle = Vehicle::new(&VehicleParams::default()).unwrap_or_else(|e| unreachable!("{e}"));
    let inputs = inputs();
    for horizon in [10usize, 20, 30] {
        let cfg = MpcConfig {
            horizon,
            ..MpcConfig::default()
        };
        let mut mpc = Mpc::new(&cfg, &vehicle).unwrap_or_else(|e| unreachable!("{e}"));
        let mut us: Vec<f64> = (0..2000)
            .map(|k| {
                let t0 = Instant::now();
                let r = mpc.step(black_box(&inputs[k % inputs.len()]));
                let dt = t0.elapsed().as_secs_f64() * 1e6;
                black_box(r.map(|o| o.tau).unwrap_or_else(|_| mpc.fallback()));
                dt
            })
            .collect();
        us.sort_by(f64::total_cmp);
        let pct = |p: f64| us[((us.len() - 1) as f64 * p).round() as usize];
        println!(
            "mpc_step P={horizon}: p50 {:.0} us, p99 {:.0} us, max {:.0} us (2000 calls)",
            pct(0.5),
            pct(0.99),
            pct(1.0)
        );
    }
    let mut group = c.benchmark_group("mpc_step");
    for horizon in [10usize, 20, 30] {
        let cfg = MpcConfig {
            horizon,
            ..MpcConfig::default()
        };
        let mut mpc = Mpc::new(&cfg, &vehicle).unwrap_or_else(|e| unreachable!("{e}"));
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
