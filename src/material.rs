//! The per-mesh component and its main-world preparation.

use bevy::{
    asset::{AssetEvent, LoadState},
    image::Image,
    math::Affine2,
    platform::collections::HashMap,
    prelude::*,
    render::extract_component::ExtractComponent,
    tasks::{AsyncComputeTaskPool, Task, block_on, poll_once},
};

use crate::{
    height_map_import::{HorizonMap, height_values, mip_chain},
    warn_once::WarnedOnce,
};

/// Marks a mesh as a mesostructure surface: the low-polygon core mesh plus a height field bound
/// to it by its UVs (paper eq. 7: `P = P0 + n0 · dis · k`).
///
/// The mesh itself is never displaced; the plugin lights it as if it were. The mesh needs
/// `Mesh::ATTRIBUTE_POSITION`, `ATTRIBUTE_NORMAL` and `ATTRIBUTE_UV_0`; without them it is drawn
/// as usual, with a one-time warning.
#[derive(Component, Reflect, Clone, Debug, PartialEq)]
#[reflect(Component, Default, Clone, Debug, PartialEq)]
pub struct MesostructureMaterial {
    /// The height field `dis(u, v)`: 1 = highest. Any single-channel, RGBA (red is used),
    /// 8-bit, 16-bit or float image; sRGB-tagged images are read as plain data, not decoded.
    /// Any size, square or not; it tiles (repeat addressing).
    pub height_map: Handle<Image>,
    /// `k`: the height of a height-map value of 1, in world units (valid: finite and > 0).
    /// The paper's valid range for unit-sized objects is 0.05–0.8: below it the structures are
    /// sub-pixel, above it larger than the object.
    pub scale: f32,
    /// Applied to the mesh UVs before the height map is sampled (tiling, offset, rotation).
    pub uv_transform: Affine2,
}

impl Default for MesostructureMaterial {
    /// No height map (nothing happens until one is set), `k = 0.1` (a tenth of a unit-sized
    /// object, mid-range of the paper's valid scales), identity UVs.
    fn default() -> Self {
        Self {
            height_map: Handle::default(),
            scale: 0.1,
            uv_transform: Affine2::IDENTITY,
        }
    }
}

/// What the render world needs of a valid [`MesostructureMaterial`]: inserted by the plugin
/// once the height map is loaded and converted, removed while the input is invalid.
#[derive(Component, ExtractComponent, Clone, Debug, PartialEq)]
pub(crate) struct PreparedMesostructure {
    /// The height map converted to an `R32Float` mip chain.
    pub height_mips: AssetId<Image>,
    /// Its texture-space horizon map ([`crate::height_map_import::HorizonMap`]): the slopes
    /// and gradient, and the distances of the slopes.
    pub horizons: AssetId<Image>,
    pub horizon_distances: AssetId<Image>,
    /// `k`, world units.
    pub scale: f32,
    /// UV transform.
    pub uv_transform: Affine2,
    /// Whether the height pass derives the shading normal from the height map (Blinn bump
    /// mapping): true unless the entity's `StandardMaterial` has a normal map of its own.
    pub bump: bool,
}

/// Converted height maps, by source image.
#[derive(Resource, Default)]
pub struct HeightMapMips(HashMap<AssetId<Image>, Derivation>);

/// A height map's derived images: built on a background task (a 512² horizon map takes
/// seconds in an unoptimised build — never on the main thread), then kept.
enum Derivation {
    /// Being built; its meshes are drawn without mesostructure until it is done.
    Building(Task<DerivedImages>),
    /// Built (`None`: the height map cannot be used).
    Done(Option<DerivedHeightMap>),
}

/// What the background task makes of a height map's values.
struct DerivedImages {
    mips: Image,
    horizons: Image,
    horizon_distances: Image,
}

/// How far the plugin is with the height maps in use, for loading screens and tests.
#[derive(Resource, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MesostructureStatus {
    /// Height maps whose mip chain and texture-space horizon map are being built in the
    /// background (their meshes are drawn without mesostructure until then).
    pub height_maps_building: usize,
    /// Height maps ready for use.
    pub height_maps_ready: usize,
}

impl MesostructureStatus {
    /// Whether `world` (an app's main world) has a height map still being built: frames meant
    /// to show the effect — a loading screen's last, a test's or a benchmark's — wait for it.
    pub fn building(world: &World) -> bool {
        world
            .get_resource::<Self>()
            .is_some_and(|s| s.height_maps_building > 0)
    }
}

/// What the plugin derives from a height map once: its mip chain and its horizon map.
#[derive(Clone, Debug)]
pub struct DerivedHeightMap {
    mips: Handle<Image>,
    horizons: Handle<Image>,
    horizon_distances: Handle<Image>,
}

/// Validates each [`MesostructureMaterial`], converts its height map once, and keeps
/// [`PreparedMesostructure`] in step.
pub(crate) fn prepare_mesostructure_materials(
    mut commands: Commands,
    materials: Query<(
        Entity,
        &MesostructureMaterial,
        Option<&PreparedMesostructure>,
        Option<&MeshMaterial3d<StandardMaterial>>,
    )>,
    standard_materials: Res<Assets<StandardMaterial>>,
    mut removed: RemovedComponents<MesostructureMaterial>,
    mut image_events: MessageReader<AssetEvent<Image>>,
    mut images: ResMut<Assets<Image>>,
    asset_server: Res<AssetServer>,
    mut mips: ResMut<HeightMapMips>,
    mut status: ResMut<MesostructureStatus>,
    mut warned: ResMut<WarnedOnce>,
) {
    for entity in removed.read() {
        if let Ok(mut e) = commands.get_entity(entity) {
            e.try_remove::<PreparedMesostructure>();
        }
    }
    for event in image_events.read() {
        if let AssetEvent::Modified { id } | AssetEvent::Removed { id } = event {
            // (A task still building is dropped, which cancels it.)
            if let Some(Derivation::Done(Some(derived))) = mips.0.remove(id) {
                images.remove(&derived.mips);
                images.remove(&derived.horizons);
                images.remove(&derived.horizon_distances);
            }
        }
    }
    for (entity, material, prepared, standard) in &materials {
        let has_normal_map = standard
            .and_then(|m| standard_materials.get(&m.0))
            .is_some_and(|m| m.normal_map_texture.is_some());
        let wanted = prepare_one(
            entity,
            material,
            &mut images,
            &asset_server,
            &mut mips,
            &mut warned,
        )
        .map(|p| PreparedMesostructure {
            bump: !has_normal_map,
            ..p
        });
        match (wanted, prepared) {
            (Some(w), Some(p)) if &w == p => {}
            (Some(w), _) => {
                commands.entity(entity).insert(w);
            }
            (None, Some(_)) => {
                commands.entity(entity).remove::<PreparedMesostructure>();
            }
            (None, None) => {}
        }
    }
    let building = mips
        .0
        .values()
        .filter(|d| matches!(d, Derivation::Building(_)))
        .count();
    let ready = mips
        .0
        .values()
        .filter(|d| matches!(d, Derivation::Done(Some(_))))
        .count();
    status.set_if_neq(MesostructureStatus {
        height_maps_building: building,
        height_maps_ready: ready,
    });
}

fn prepare_one(
    entity: Entity,
    material: &MesostructureMaterial,
    images: &mut Assets<Image>,
    asset_server: &AssetServer,
    mips: &mut HeightMapMips,
    warned: &mut WarnedOnce,
) -> Option<PreparedMesostructure> {
    if !(material.scale.is_finite() && material.scale > 0.0) {
        warned.warn(format!("scale {entity}"), || {
            format!(
                "entity {entity}: MesostructureMaterial::scale is {}, but must be finite and > 0; \
                 the mesh is drawn without mesostructure until it is fixed",
                material.scale
            )
        });
        return None;
    }
    warned.forget(&format!("scale {entity}"));
    if !material.uv_transform.is_finite() {
        warned.warn(format!("uv {entity}"), || {
            format!("entity {entity}: MesostructureMaterial::uv_transform is not finite; ignored")
        });
        return None;
    }
    let id = material.height_map.id();
    if material.height_map == Handle::default() {
        warned.warn(format!("missing {id} {entity}"), || {
            format!(
                "entity {entity}: MesostructureMaterial::height_map is not set; the mesh is \
                     drawn without mesostructure"
            )
        });
        return None;
    }
    if !mips.0.contains_key(&id) {
        let Some(source) = images.get(id) else {
            match asset_server.get_load_state(id) {
                Some(LoadState::Loading) => {}
                Some(LoadState::Failed(err)) => {
                    warned.warn(format!("failed {id}"), || {
                        format!(
                            "entity {entity}: the height map failed to load ({err}); \
                                 the mesh is drawn without mesostructure"
                        )
                    });
                }
                _ => {
                    warned.warn(format!("missing {id}"), || {
                        format!(
                            "entity {entity}: MesostructureMaterial::height_map is not set \
                                 or not an image asset; the mesh is drawn without mesostructure"
                        )
                    });
                }
            }
            return None;
        };
        let derived = match height_values(source) {
            Ok((values, notes)) => {
                for note in notes {
                    warned.warn(format!("note {id} {note}"), || {
                        format!("height map {id}: {note}")
                    });
                }
                let (w, h) = (source.width(), source.height());
                Derivation::Building(AsyncComputeTaskPool::get().spawn(async move {
                    let horizons = HorizonMap::new(&values, w, h);
                    DerivedImages {
                        horizons: horizons.to_image(),
                        horizon_distances: horizons.distance_image(),
                        mips: mip_chain(values, w, h),
                    }
                }))
            }
            Err(err) => {
                warned.warn(format!("convert {id}"), || {
                    format!(
                        "entity {entity}: cannot use the height map: {err}; \
                             the mesh is drawn without mesostructure"
                    )
                });
                Derivation::Done(None)
            }
        };
        mips.0.insert(id, derived);
    }
    let derivation = mips.0.get_mut(&id)?;
    if let Derivation::Building(task) = derivation {
        let built = block_on(poll_once(task))?;
        *derivation = Derivation::Done(Some(DerivedHeightMap {
            mips: images.add(built.mips),
            horizons: images.add(built.horizons),
            horizon_distances: images.add(built.horizon_distances),
        }));
    }
    let Derivation::Done(Some(derived)) = derivation else {
        return None;
    };
    Some(PreparedMesostructure {
        height_mips: derived.mips.id(),
        horizons: derived.horizons.id(),
        horizon_distances: derived.horizon_distances.id(),
        scale: material.scale,
        uv_transform: material.uv_transform,
        bump: true,
    })
}

/// On an entity whose `StandardMaterial` the plugin swapped for its mesostructure copy: the
/// user's own material, restored when the entity stops being a mesostructure surface.
#[derive(Component, Clone, Debug)]
pub struct AdaptedMaterial {
    /// The material the user gave the entity.
    pub original: Handle<StandardMaterial>,
    /// The copy the entity renders with: deferred, lit by the mesostructure lighting pass.
    pub adapted: Handle<StandardMaterial>,
}

/// Mesostructure copies of user materials, by original; shared by the entities that share the
/// original, so other users of a material are never changed.
#[derive(Resource, Default)]
pub struct AdaptedMaterials(HashMap<AssetId<StandardMaterial>, Handle<StandardMaterial>>);

/// The mesostructure copy of a material: rendered deferred, with the mesostructure lighting
/// pass id, so that Bevy's lighting pass leaves its pixels to ours.
pub fn adapt(material: &StandardMaterial) -> StandardMaterial {
    StandardMaterial {
        opaque_render_method: bevy::material::OpaqueRendererMethod::Deferred,
        deferred_lighting_pass_id: crate::render::lighting::MESOSTRUCTURE_LIGHTING_PASS_ID,
        ..material.clone()
    }
}

/// Swaps the `StandardMaterial` of each prepared mesostructure entity for its mesostructure
/// copy (keeping the copy in step with the original), and restores the original when the
/// entity is no longer one.
pub(crate) fn adapt_standard_materials(
    mut commands: Commands,
    entities: Query<(
        Entity,
        &MeshMaterial3d<StandardMaterial>,
        Has<PreparedMesostructure>,
        Option<&AdaptedMaterial>,
    )>,
    mut materials: ResMut<Assets<StandardMaterial>>,
    mut adapted: ResMut<AdaptedMaterials>,
    mut events: MessageReader<AssetEvent<StandardMaterial>>,
) {
    for event in events.read() {
        if let AssetEvent::Modified { id } = event
            && let Some(copy) = adapted.0.get(id).cloned()
            && let Some(original) = materials.get(*id).map(adapt)
            && let Some(mut target) = materials.get_mut(&copy)
        {
            *target = original;
        }
    }
    for (entity, material, prepared, swapped) in &entities {
        match (prepared, swapped) {
            (true, Some(s)) if material.0 == s.adapted => {}
            (true, _) => {
                // New, or the user set another material since: that one is the original now.
                let original = material.0.clone();
                let copy = match adapted.0.get(&original.id()) {
                    Some(copy) => copy.clone(),
                    None => {
                        let Some(source) = materials.get(&original).map(adapt) else {
                            continue;
                        };
                        let copy = materials.add(source);
                        adapted.0.insert(original.id(), copy.clone());
                        copy
                    }
                };
                commands.entity(entity).insert((
                    MeshMaterial3d(copy.clone()),
                    AdaptedMaterial {
                        original,
                        adapted: copy,
                    },
                ));
            }
            (false, Some(s)) => {
                let mut e = commands.entity(entity);
                if material.0 == s.adapted {
                    e.insert(MeshMaterial3d(s.original.clone()));
                }
                e.remove::<AdaptedMaterial>();
            }
            (false, None) => {}
        }
    }
}
