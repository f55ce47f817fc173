//! MPC solve time (linearise + condense + clarabel) at P = 10, 20, 30 with the default
//! move blocking (5 moves), on a moving, turning target with the state changing each call.
//!
//! `cargo bench -p mpc --bench mpc`

use std::hint::black_box;

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
