use super::*;

#[test]
fn the_cache_gives_back_the_same_transport_and_rejects_anything_else() {
    let ball = mesh_object(
        Sphere::new(0.05).mesh().ico(2).unwrap(),
        Transform::from_xyz(0.0, 0.05, 0.0),
    );
    let floor = mesh_object(
        Plane3d::new(Vec3::Y, Vec2::splat(0.2)).mesh().build(),
        Transform::IDENTITY,
    );
    let objects = [ball, floor];
    let views = views_of(&objects);
    let surfaces = [
        PatchSurface::Translucent {
            medium: TranslucentPreset::Skin1.medium(),
            world_units_per_mm: 0.001,
            oriented_dipole: false,
        },
        PatchSurface::Opaque {
            albedo: Vec3::splat(0.8),
        },
    ];
    let patches = resample_into_patches(&views, 200);
    let rays = SceneRays::new(&views);
    // With a (small) beam table, which the cache keeps too, its exit directions and where its
    // single scattering goes included.
    let table = crate::translucency::beam_table::BeamTableSettings {
        walks: 4,
        late_walks: 4,
        exit_directions: true,
        single_scattering_to_pixels: true,
        ..default()
    };
    let settings = TransportSettings {
        beam_table: Some(table),
        ..default()
    };
    let transport = EnergyTransport::build(&patches, &surfaces, &rays, &settings);
    assert!(transport.beam_table.as_ref().is_some_and(|t| t.early.entries() > 0 && t.early_leaving.len() == t.early.entries()));
    let dir = std::env::temp_dir().join(format!("bevy_mesostructure_cache_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("scene.translucency");
    crate::translucency::cache::save(&path, &patches, &transport).unwrap();
    let (p, t) = crate::translucency::cache::load(&path).unwrap();
    assert_eq!(p.patches, patches.patches);
    assert_eq!(p.samples, patches.samples);
    assert_eq!(p.sample_offsets, patches.sample_offsets);
    assert_eq!(p.object_patch_sizes, patches.object_patch_sizes);
    assert_eq!(t.scattering, transport.scattering);
    assert_eq!(t.form_factors, transport.form_factors);
    assert_eq!(t.cluster_means, transport.cluster_means);
    assert_eq!(t.single_scattering, transport.single_scattering);
    assert_eq!(t.areas, transport.areas);
    assert_eq!(t.report, transport.report);
    assert_eq!(t.beam_table, transport.beam_table);
    // Cut short, or not a cache at all: an error, never a panic or a wrong transport.
    let bytes = std::fs::read(&path).unwrap();
    for cut in [0, 7, 100, bytes.len() / 2, bytes.len() - 1] {
        std::fs::write(&path, &bytes[..cut]).unwrap();
        assert!(crate::translucency::cache::load(&path).is_err(), "cut at {cut}");
    }
    let mut flipped = bytes.clone();
    flipped[8] ^= 0xff;
    std::fs::write(&path, &flipped).unwrap();
    assert!(crate::translucency::cache::load(&path).is_err());
    std::fs::remove_dir_all(&dir).unwrap();
    // The key follows what the transport depends on.
    let key = |surfaces: &[PatchSurface], budget| {
        let keyed: Vec<_> = objects
            .iter()
            .zip(surfaces)
            .map(|(o, s)| (o.0.as_slice(), o.1.as_slice(), *s))
            .collect();
        crate::translucency::cache::scene_key(&keyed, budget, &settings)
    };
    let base = key(&surfaces, 200);
    assert_eq!(base, key(&surfaces, 200));
    assert_ne!(base, key(&surfaces, 201));
    let mut other = surfaces;
    other[1] = PatchSurface::Opaque {
        albedo: Vec3::splat(0.7),
    };
    assert_ne!(base, key(&other, 200));
    let without = TransportSettings { beam_table: None, ..default() };
    let keyed: Vec<_> = objects
        .iter()
        .zip(&surfaces)
        .map(|(o, s)| (o.0.as_slice(), o.1.as_slice(), *s))
        .collect();
    assert_ne!(base, crate::translucency::cache::scene_key(&keyed, 200, &without));
    // The settings only derived from a built transport (the exit laws', the beams'
    // incidence) keep its key: the plugin derives them again on the transport it has.
    let toggled = TransportSettings {
        deep_exit_law: !settings.deep_exit_law,
        exit_lobes: !settings.exit_lobes,
        flow_law_takes_all: !settings.flow_law_takes_all,
        tangential_flux: !settings.tangential_flux,
        beam_incidence: !settings.beam_incidence,
        ..settings
    };
    assert_eq!(base, crate::translucency::cache::scene_key(&keyed, 200, &toggled));
    assert!(toggled.derived().iter().zip(settings.derived()).all(|(a, b)| *a != b), "all five are derived");
    assert_eq!(settings.with_derived_from(&toggled), toggled);
    assert_eq!(toggled.with_derived_from(&settings), settings);
}

/// The gather's grid keeps each member's own cell beside it (the pass takes a member only
/// from the cell it walks: two of the 27 cells about a pixel may hash to one bucket, and its
/// patches counted twice — with photons, twice the light); every patch is in one bucket once.
#[test]
fn the_gathers_grid_keeps_each_members_own_cell() {
    use crate::translucency::gather::PatchGrid;
    let centres: Vec<Vec3> = (0..500)
        .map(|i| Vec3::new(i as f32 * 0.1 - 20.0, (i % 7) as f32 * -0.3, (i % 11) as f32 * 0.2))
        .collect();
    let indices: Vec<u32> = (0..500).collect();
    let grid = PatchGrid::new(&centres, &indices, 0.3);
    let mask = (grid.offsets.len() - 2) as u32;
    assert_eq!(grid.members.len(), 500);
    assert_eq!(grid.cells.len(), 500);
    let mut seen = vec![0; 500];
    for b in 0..grid.offsets.len() - 1 {
        for k in grid.offsets[b] as usize..grid.offsets[b + 1] as usize {
            let i = grid.members[k] as usize;
            seen[i] += 1;
            let cell = (centres[i] / 0.3).floor().as_ivec3();
            assert_eq!(grid.cells[k], cell);
            assert_eq!(PatchGrid::bucket(cell, mask), b as u32);
        }
    }
    assert!(seen.iter().all(|&n| n == 1));
}

/// The products the next warm solve records after one that took `taken` of `recorded`: one
/// more than it took, or the whole cap where it took all it was given (it may have needed
/// more) — `ProductsReadback`'s rule.
#[test]
fn a_solve_that_took_every_recorded_product_asks_for_the_whole_cap_next() {
    use crate::translucency::iteration::next_products;
    assert_eq!(next_products(6, 6, 2), 3);
    assert_eq!(next_products(6, 3, 2), 3);
    assert_eq!(next_products(6, 4, 4), 6, "stopped by what was recorded");
    assert_eq!(next_products(6, 16, 10), 6, "after a cold solve: the warm cap");
    assert_eq!(next_products(6, 6, 0), 1, "at least one");
}
