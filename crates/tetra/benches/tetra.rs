//! Speed of the tetra stage: per-vertex gradients of a 5-million-tetrahedra
//! mesh and the default 128 x 128 x 256 F/B table pair.
//! `cargo bench -p mdtf-tetra`.

use mdtf_datagen::erf_sphere;
use mdtf_tetra::{GradientMethod, TetMesh, TetScheme, tetrahedralise, vertex_gradients};
use mdtf_volume::Geometry;

fn main() {
    divan::main();
}

/// 95^3 grid, 6 tetrahedra per cell: 94^3 x 6 = 4.98 million tetrahedra.
fn five_million() -> TetMesh {
    let g = Geometry::new([95, 95, 95], [1.0; 3]);
    let v = erf_sphere(g, 30.0, 3.0, 0.0, 255.0, None).volume();
    tetrahedralise(&v, TetScheme::Six, "v").expect("mesh")
}

#[divan::bench(sample_count = 5, args = [GradientMethod::LeastSquares, GradientMethod::VolumeAverage])]
fn vertex_gradients_5m_tets(b: divan::Bencher, method: GradientMethod) {
    let mesh = five_million();
    b.counter(divan::counter::ItemsCount::new(mesh.tets.len()))
        .bench(|| vertex_gradients(divan::black_box(&mesh), method));
}

#[divan::bench(sample_count = 5)]
fn front_back_table_128x128x256(b: divan::Bencher) {
    b.bench(|| mdtf_pack::front_back_tables(divan::black_box([128, 128, 256]), 8.0, 2.0));
}
