//! Time of one RK4 step of the 6-DOF model (target < 2 µs) and of one `nu_dot` evaluation.
//!
//! `cargo bench -p sim-plant --bench plant`

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{UnitQuaternion, Vector3, Vector6};
use sim_plant::model::Vehicle;
use sim_plant::{Plant, PlantConfig, PlantState, VehicleParams};

fn bench_plant(c: &mut Criterion) {
    let config = PlantConfig {
        current_ned_mps: [0.2, -0.1, 0.0],
        ..PlantConfig::default()
    };
    let start = PlantState {
        position_ned_m: Vector3::new(0.0, 0.0, 10.0),
        attitude: UnitQuaternion::from_euler_angles(0.1, -0.05, 0.3),
        nu: Vector6::new(1.5, 0.1, -0.05, 0.02, 0.01, 0.05),
    };
    let mut plant = Plant::new(&config, start).unwrap_or_else(|e| unreachable!("{e}"));
    let tau = Vector6::new(200.0, 10.0, -5.0, 1.0, 2.0, -3.0);
    c.bench_function("plant_rk4_step_0.01s", |b| {
        b.iter(|| {
            // One substep of step_s; under constant thrust the state settles into a steady turn.
            if plant.advance(black_box(&tau), black_box(0.01)).is_err() {
                unreachable!();
            }
        });
    });
    let v = Vehicle::new(&VehicleParams::default()).unwrap_or_else(|e| unreachable!("{e}"));
    c.bench_function("vehicle_nu_dot", |b| {
        b.iter(|| {
            v.nu_dot(
                black_box(&start.nu),
                black_box(&start.attitude),
                black_box(&tau),
            )
        });
    });
}

criterion_group!(benches, bench_plant);
criterion_main!(benches);
