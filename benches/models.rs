//! Cost per call of the model functions (D, G1, Lambda, the visible-normal pdf and the exact sampler of
//! Walter et al. sec. 4.1, the canonical form). Run: `cargo bench --bench models`.

use std::hint::black_box;

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::Vector3;
use ndfit::models::{Ellipsoid, Masking, Model, ModelId, Ndf};

fn bench(c: &mut Criterion) {
    let m = Vector3::new(0.2, -0.1, 0.97).normalize();
    let u = Vector3::new(-0.5, 0.3, 0.8).normalize();
    let models = [
        Model::from_params(ModelId::Ggx, &[0.2]).expect("valid"),
        Model::from_params(ModelId::BeckmannAniso, &[0.2, 0.1, 0.4]).expect("valid"),
        Model::from_params(ModelId::Ellipsoid, &[0.2, 0.1, 0.3, -0.2, 0.4]).expect("valid"),
    ];
    for model in models {
        let id = model.id();
        c.bench_function(&format!("{id} d"), |b| b.iter(|| black_box(model).d(black_box(m))));
        c.bench_function(&format!("{id} g1"), |b| b.iter(|| Masking::g1(&black_box(model), black_box(u), black_box(m))));
        c.bench_function(&format!("{id} canonical"), |b| b.iter(|| black_box(model).canonical()));
    }
    let e = Ellipsoid::from_params(0.2, 0.1, 0.3, -0.2, 0.4).expect("valid");
    c.bench_function("ellipsoid pdf_visible_normal", |b| b.iter(|| black_box(e).pdf_visible_normal(black_box(u), black_box(m))));
    c.bench_function("ellipsoid sample_visible_normal", |b| {
        b.iter(|| black_box(e).sample_visible_normal(black_box(u), black_box([0.3, 0.7])))
    });
    c.bench_function("ellipsoid from_matrix (SVD)", |b| b.iter(|| Ellipsoid::from_matrix(black_box(e.a()))));
}

criterion_group!(benches, bench);
criterion_main!(benches);
