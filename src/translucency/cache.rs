//! The precompute on disk: a scene's patches and transport, keyed by everything they depend
//! on (every participant's world-space triangles and surface, the budget, the transport
//! settings and this crate's version), so that a static level loads its transport instead of
//! building it again. A little-endian binary of its own: a magic tag, then each array with
//! its length; anything that does not read back whole is rejected (and rebuilt by the caller).

use std::{
    io::{self, Read, Write},
    path::Path,
};

use bevy::prelude::*;

use super::{
    beam_table::{BeamTable, BeamTableSettings, ExitLean},
    patches::{Patch, PatchSample, Patches},
    transport::{EnergyTransport, PatchSurface, SparseMatrix, TransportReport, TransportSettings},
};

/// The file format's tag (09: the beam table's settings hold `max_last_order`).
const MAGIC: &[u8; 8] = b"BMSTRN09";

/// FNV-1a, 64 bits: the cache's key and the plugin's change signatures.
#[derive(Clone, Copy)]
pub(crate) struct Hash(pub(crate) u64);

impl Hash {
    pub(crate) fn new() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
    pub(crate) fn bytes(mut self, bytes: &[u8]) -> Self {
        for &b in bytes {
            self.0 = (self.0 ^ b as u64).wrapping_mul(0x0100_0000_01b3);
        }
        self
    }
    pub(crate) fn f32s(self, values: impl IntoIterator<Item = f32>) -> Self {
        values
            .into_iter()
            .fold(self, |h, v| h.bytes(&v.to_le_bytes()))
    }
}

/// Bumped when the same settings come to build a different transport, so that files of the
/// old one are not found (2: the beam table's walks shared by the colour channels; 3: its
/// beam walks split far from their entry, `BeamTableSettings::far_splits`; 4: objects above
/// `MAX_SHAPE_PATCHES` solved in their shape on clusters of their patches; 5: the far split
/// and the exit lobes never nearer than two transport mean free paths, `lobe_source_distance`;
/// 6: every ray started at least `rays::MIN_BACK_OFF` behind its origin, so that walks no
/// longer slip out through a surface on flights under 0.1 mm in a scene in metres; 7: the
/// late light's walks scaled by `(ℓ/h)²`, patches per square transport mean free path,
/// `beam_table::build::late_walks_for`; 8: a clustered shape solve collocated at each
/// cluster's area-weighted centre; 9: walks in a medium that barely absorbs go on past
/// `last_order`, `BeamTableSettings::max_last_order`; 10: a beam's walks enter by projected
/// area, none through a sample that faces away from it; 11: the shape solve's self term from
/// Gauss's identity, `shape_diffusion::boundary_correction`; 12: the late light's walks
/// scaled by `order/32` in a medium walked past 32 scatterings, `late_walks_for`; 13: `K`'s
/// columns on tabled patches from their late light's diffuse walks,
/// `BeamTableSettings::diffuse_columns_walked`).
const REVISION: u32 = 13;

/// The cache key of a scene: its objects (world-space positions, indices, surface), the
/// patch budget, the transport settings, the crate's version and [`REVISION`].
pub fn scene_key(
    objects: &[(&[Vec3], &[u32], PatchSurface)],
    budget: usize,
    settings: &TransportSettings,
) -> u64 {
    let mut h = Hash::new()
        .bytes(env!("CARGO_PKG_VERSION").as_bytes())
        .bytes(&REVISION.to_le_bytes())
        .bytes(&(budget as u64).to_le_bytes())
        .bytes(format!("{:?}", settings.kernel).as_bytes())
        .f32s([
            settings.diffusion_energy_kept,
            settings.form_factor_cutoff,
            settings.far_field_ratio,
            settings.cluster_size as f32,
            settings.object_exit_share as u32 as f32,
            settings.shape_diffusion as u32 as f32,
            settings.shape_energy_dropped,
        ])
        .bytes(format!("{:?}", settings.beam_table).as_bytes());
    for (positions, indices, surface) in objects {
        h = h.f32s(positions.iter().flat_map(|p| p.to_array()));
        h = indices.iter().fold(h, |h, i| h.bytes(&i.to_le_bytes()));
        h = match surface {
            PatchSurface::Opaque { albedo } => h.bytes(b"opaque").f32s(albedo.to_array()),
            PatchSurface::Translucent {
                medium,
                world_units_per_mm,
                oriented_dipole,
            } => h
                .bytes(b"translucent")
                .f32s(medium.absorption.to_array())
                .f32s(medium.reduced_scattering.to_array())
                .f32s([medium.index_of_refraction, *world_units_per_mm])
                .bytes(&[*oriented_dipole as u8]),
        };
    }
    h.0
}

struct Writer<W: Write>(W);

impl<W: Write> Writer<W> {
    fn u32s(&mut self, v: &[u32]) -> io::Result<()> {
        self.0.write_all(&(v.len() as u64).to_le_bytes())?;
        for x in v {
            self.0.write_all(&x.to_le_bytes())?;
        }
        Ok(())
    }
    fn f32s(&mut self, v: impl ExactSizeIterator<Item = f32>) -> io::Result<()> {
        self.0.write_all(&(v.len() as u64).to_le_bytes())?;
        for x in v {
            self.0.write_all(&x.to_le_bytes())?;
        }
        Ok(())
    }
}

struct Reader<R: Read>(R);

impl<R: Read> Reader<R> {
    fn len(&mut self) -> io::Result<usize> {
        let mut b = [0u8; 8];
        self.0.read_exact(&mut b)?;
        let n = u64::from_le_bytes(b);
        // A corrupt length must not allocate the machine away.
        if n > (1 << 34) {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                "implausible array length",
            ));
        }
        Ok(n as usize)
    }
    fn u32s(&mut self) -> io::Result<Vec<u32>> {
        let n = self.len()?;
        let mut bytes = vec![0u8; n * 4];
        self.0.read_exact(&mut bytes)?;
        Ok(bytes
            .chunks_exact(4)
            .map(|c| u32::from_le_bytes(c.try_into().unwrap()))
            .collect())
    }
    fn f32s(&mut self) -> io::Result<Vec<f32>> {
        Ok(self.u32s()?.into_iter().map(f32::from_bits).collect())
    }
}

fn vec3s(v: &[f32]) -> Vec<Vec3> {
    v.chunks_exact(3).map(Vec3::from_slice).collect()
}

type RawMatrix = (Vec<u32>, Vec<u32>, Vec<f32>);

fn read_matrix<R: Read>(r: &mut Reader<R>) -> io::Result<RawMatrix> {
    Ok((r.u32s()?, r.u32s()?, r.f32s()?))
}

/// Offsets rising to the entry count, `rows` rows where given, columns below `columns`,
/// `width` values per entry.
fn consistent(m: &RawMatrix, rows: Option<usize>, columns: usize, width: usize) -> bool {
    let (offsets, cols, values) = m;
    rows.is_none_or(|rows| offsets.len() == rows + 1)
        && !offsets.is_empty()
        && offsets.windows(2).all(|w| w[0] <= w[1])
        && offsets.last().copied().unwrap_or(0) as usize == cols.len()
        && values.len() == cols.len() * width
        && cols.iter().all(|&c| (c as usize) < columns)
}

fn invalid(what: &str) -> io::Error {
    io::Error::new(io::ErrorKind::InvalidData, what.to_string())
}

/// Writes `patches` and `transport` to `path` (through a temporary file, renamed when whole).
pub fn save(path: &Path, patches: &Patches, transport: &EnergyTransport) -> io::Result<()> {
    let temporary = path.with_extension("partial");
    {
        let mut w = Writer(io::BufWriter::new(std::fs::File::create(&temporary)?));
        w.0.write_all(MAGIC)?;
        let p = &patches.patches;
        w.f32s(
            p.iter()
                .flat_map(|q| {
                    [
                        q.centre.to_array(),
                        q.surface_point.to_array(),
                        q.normal.to_array(),
                    ]
                    .concat()
                    .into_iter()
                    .chain([q.area])
                })
                .collect::<Vec<_>>()
                .into_iter(),
        )?;
        w.u32s(&p.iter().map(|q| q.object).collect::<Vec<_>>())?;
        w.f32s([patches.patch_size].into_iter())?;
        w.f32s(patches.object_patch_sizes.iter().copied())?;
        w.u32s(&[patches.skipped_triangles as u32])?;
        w.f32s(
            patches
                .samples
                .iter()
                .flat_map(|s| {
                    [
                        s.position.to_array(),
                        s.normal.to_array(),
                        [s.area, 0.0, 0.0],
                    ]
                    .concat()
                })
                .collect::<Vec<_>>()
                .into_iter(),
        )?;
        w.u32s(&patches.sample_offsets)?;
        let k = &transport.scattering;
        w.u32s(&k.row_offsets)?;
        w.u32s(&k.columns)?;
        w.f32s(
            k.values
                .iter()
                .flat_map(|v| v.to_array())
                .collect::<Vec<_>>()
                .into_iter(),
        )?;
        for m in [&transport.form_factors, &transport.cluster_means] {
            w.u32s(&m.row_offsets)?;
            w.u32s(&m.columns)?;
            w.f32s(m.values.iter().copied())?;
        }
        w.f32s(
            transport
                .single_scattering
                .iter()
                .flat_map(|v| v.to_array())
                .collect::<Vec<_>>()
                .into_iter(),
        )?;
        w.f32s(transport.areas.iter().copied())?;
        let r = &transport.report;
        w.u32s(&[
            r.form_factor_entries as u32,
            r.clusters as u32,
            r.scattering_entries as u32,
            r.rays as u32,
            r.shape_solved_objects as u32,
            r.shape_clustered_objects as u32,
            r.beam_table_skipped as u32,
        ])?;
        w.f32s(
            [
                r.dropped_form_factor_mean,
                r.dropped_form_factor_max,
                r.diffusion_kept_mean.x,
                r.diffusion_kept_mean.y,
                r.diffusion_kept_mean.z,
                r.seconds,
                r.object_exit_over_slab_mean.x,
                r.object_exit_over_slab_mean.y,
                r.object_exit_over_slab_mean.z,
            ]
            .into_iter(),
        )?;
        // The beam table, if any: its settings (none: an empty list), slots, media, the late
        // shares, the early and late columns, then the early entries' leaving directions.
        match &transport.beam_table {
            None => w.u32s(&[])?,
            Some(t) => {
                let s = &t.settings;
                // The two flags share one word (bit 0 the exit directions, bit 1 single
                // scattering left to the pixels): files written before bit 1 read as before.
                let flags = u32::from(s.exit_directions)
                    | u32::from(s.single_scattering_to_pixels) << 1
                    | u32::from(s.diffuse_columns_walked) << 2;
                w.u32s(&[s.cosines, s.azimuths, s.walks, s.late_walks, s.last_order, flags, s.seed, s.far_splits, s.max_last_order])?;
                w.u32s(&t.slots)?;
                w.f32s(t.media.iter().flat_map(|m| m.to_array()).collect::<Vec<_>>().into_iter())?;
                w.f32s(t.late_share.iter().flat_map(|v| v.to_array()).collect::<Vec<_>>().into_iter())?;
                for m in [&t.early, &t.late] {
                    w.u32s(&m.row_offsets)?;
                    w.u32s(&m.columns)?;
                    w.f32s(m.values.iter().flat_map(|v| v.to_array()).collect::<Vec<_>>().into_iter())?;
                }
                w.f32s(t.early_leaving.iter().flatten().flat_map(|v| v.to_array()).collect::<Vec<_>>().into_iter())?;
                w.f32s(t.exit_lean.iter().flat_map(|l| l.along.to_array().into_iter().chain(l.across.to_array())).collect::<Vec<_>>().into_iter())?;
                w.f32s([t.seconds].into_iter())?;
            }
        }
        w.0.flush()?;
    }
    std::fs::rename(&temporary, path)
}

/// Reads back what [`save`] wrote; an error for anything else or anything inconsistent.
pub fn load(path: &Path) -> io::Result<(Patches, EnergyTransport)> {
    let mut r = Reader(io::BufReader::new(std::fs::File::open(path)?));
    let mut magic = [0u8; 8];
    r.0.read_exact(&mut magic)?;
    if &magic != MAGIC {
        return Err(invalid("not a translucency cache of this version"));
    }
    let records = r.f32s()?;
    let objects = r.u32s()?;
    if records.len() != objects.len() * 10 {
        return Err(invalid("patch records"));
    }
    let patches_list: Vec<Patch> = records
        .chunks_exact(10)
        .zip(&objects)
        .map(|(c, &object)| Patch {
            centre: Vec3::from_slice(&c[0..3]),
            surface_point: Vec3::from_slice(&c[3..6]),
            normal: Vec3::from_slice(&c[6..9]),
            area: c[9],
            object,
        })
        .collect();
    let patch_size = *r.f32s()?.first().ok_or_else(|| invalid("patch size"))?;
    let object_patch_sizes = r.f32s()?;
    let skipped = *r.u32s()?.first().ok_or_else(|| invalid("skipped"))? as usize;
    let sample_data = r.f32s()?;
    let samples: Vec<PatchSample> = sample_data
        .chunks_exact(9)
        .map(|c| PatchSample {
            position: Vec3::from_slice(&c[0..3]),
            normal: Vec3::from_slice(&c[3..6]),
            area: c[6],
        })
        .collect();
    let sample_offsets = r.u32s()?;
    let n = patches_list.len();
    let max_object = patches_list
        .iter()
        .map(|p| p.object as usize + 1)
        .max()
        .unwrap_or(0);
    if sample_offsets.len() != n + 1
        || sample_offsets.last().copied().unwrap_or(0) as usize != samples.len()
        || sample_offsets.windows(2).any(|w| w[0] > w[1])
        || object_patch_sizes.len() < max_object
    {
        return Err(invalid("patch samples"));
    }
    // K (patches × patches, RGB), F (patches × patches and clusters), the cluster means
    // (clusters × patches): read whole, then checked against one another.
    let k = read_matrix(&mut r)?;
    let f = read_matrix(&mut r)?;
    let c = read_matrix(&mut r)?;
    let clusters = c.0.len().saturating_sub(1);
    if !consistent(&k, Some(n), n, 3)
        || !consistent(&f, Some(n), n + clusters, 1)
        || !consistent(&c, None, n, 1)
    {
        return Err(invalid("sparse matrices"));
    }
    let scattering = SparseMatrix {
        row_offsets: k.0,
        columns: k.1,
        values: vec3s(&k.2),
    };
    let (f_offsets, f_columns, f_values) = f;
    let (co, cc, cv) = c;
    let single_scattering = vec3s(&r.f32s()?);
    let areas = r.f32s()?;
    let counts = r.u32s()?;
    let figures = r.f32s()?;
    if single_scattering.len() != n || areas.len() != n || counts.len() != 7 || figures.len() != 9 {
        return Err(invalid("transport vectors"));
    }
    let beam_table = read_beam_table(&mut r, n)?;
    let patches = Patches {
        patches: patches_list,
        patch_size,
        object_patch_sizes,
        skipped_triangles: skipped,
        samples,
        sample_offsets,
    };
    let transport = EnergyTransport {
        scattering,
        form_factors: SparseMatrix {
            row_offsets: f_offsets,
            columns: f_columns,
            values: f_values,
        },
        cluster_means: SparseMatrix {
            row_offsets: co,
            columns: cc,
            values: cv,
        },
        single_scattering,
        areas,
        // Per frame only, from the surfaces the loader has (`incidence_weights`).
        incidence: Vec::new(),
        report: TransportReport {
            form_factor_entries: counts[0] as usize,
            clusters: counts[1] as usize,
            scattering_entries: counts[2] as usize,
            rays: counts[3] as usize,
            shape_solved_objects: counts[4] as usize,
            shape_clustered_objects: counts[5] as usize,
            beam_table_skipped: counts[6] as usize,
            dropped_form_factor_mean: figures[0],
            dropped_form_factor_max: figures[1],
            diffusion_kept_mean: Vec3::new(figures[2], figures[3], figures[4]),
            seconds: figures[5],
            object_exit_over_slab_mean: Vec3::new(figures[6], figures[7], figures[8]),
            beam_table_entries: beam_table
                .as_ref()
                .map_or(0, |t| t.early.entries() + t.late.entries()),
        },
        beam_table,
    };
    Ok((patches, transport))
}

/// The beam table [`save`] wrote after the transport, checked against `n` patches.
fn read_beam_table<R: Read>(r: &mut Reader<R>, n: usize) -> io::Result<Option<BeamTable>> {
    let settings = r.u32s()?;
    let [cosines, azimuths, walks, late_walks, last_order, flags, seed, far_splits, max_last_order] = settings[..] else {
        return if settings.is_empty() { Ok(None) } else { Err(invalid("beam table settings")) };
    };
    let settings = BeamTableSettings {
        cosines,
        azimuths,
        walks,
        late_walks,
        far_splits,
        last_order,
        max_last_order,
        exit_directions: flags & 1 != 0,
        single_scattering_to_pixels: flags & 2 != 0,
        diffuse_columns_walked: flags & 4 != 0,
        seed,
        // Not kept: it decides whether a table is built, not what it holds.
        max_patches: BeamTableSettings::default().max_patches,
    };
    if settings.invalid_reason().is_some() {
        return Err(invalid("beam table settings"));
    }
    let slots = r.u32s()?;
    let media: Vec<Vec4> = r.f32s()?.chunks_exact(4).map(Vec4::from_slice).collect();
    let late_share = vec3s(&r.f32s()?);
    let early = read_matrix(r)?;
    let late = read_matrix(r)?;
    let leaving: Vec<Vec4> = r.f32s()?.chunks_exact(4).map(Vec4::from_slice).collect();
    let lean = r.f32s()?;
    let seconds = r.f32s()?;
    let (count, bins) = (media.len(), settings.bins() as usize);
    if slots.len() != n
        || slots.iter().any(|&s| s != u32::MAX && s as usize >= count)
        || late_share.len() != count * bins
        || !consistent(&early, Some(n), count * bins, 3)
        || !consistent(&late, Some(n), count, 3)
        || leaving.len() != if settings.exit_directions { early.1.len() * 3 } else { 0 }
        || lean.len() != count * 6
        || seconds.len() != 1
    {
        return Err(invalid("beam table"));
    }
    let matrix = |(row_offsets, columns, values): RawMatrix| SparseMatrix {
        row_offsets,
        columns,
        values: vec3s(&values),
    };
    Ok(Some(BeamTable {
        settings,
        slots,
        media,
        late_share,
        early_leaving: leaving.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        early: matrix(early),
        late: matrix(late),
        exit_lean: lean
            .chunks_exact(6)
            .map(|l| ExitLean { along: Vec3::from_slice(&l[0..3]), across: Vec3::from_slice(&l[3..6]) })
            .collect(),
        seconds: seconds[0],
    }))
}
