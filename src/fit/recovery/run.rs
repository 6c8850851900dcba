//! The recovery loop as a value: [`RecoveryLoop::start`] or [`RecoveryLoop::resume`], then
//! [`RecoveryLoop::iterate`] (one global iteration) until [`RecoveryLoop::converged`], then
//! [`RecoveryLoop::finish`] (the final render). Between iterations,
//! [`RecoveryLoop::checkpoint`] is the whole state needed to continue.
//!
//! Every global iteration re-renders what each fitted group sees with *all* current parameters
//! (so light bounced off a surface whose BRDF changed reaches the others), refits each group on
//! its fresh cache and lets the hierarchy decide its level (§4.1, Figure 1 of the notes). Groups
//! are visited in turn and each one's new parameters enter the scene at once (Gauss–Seidel), so
//! a group's cache already sees the groups refitted before it in the same iteration: this
//! converges in fewer iterations than updating all groups at the end (bench/README.md).

use super::checkpoint::{Checkpoint, CHECKPOINT_VERSION};
use super::options::{
    pixel_budget, LogLine, PhotoView, RecoverError, RecoverOptions, Recovery, ViewFit,
};
use crate::fit::cache::{choose_pixels, CacheOptions};
use crate::fit::error::{block_side, block_tile, tiled_error, PixelTerms};
use crate::fit::event::Event;
use crate::fit::group::{GroupState, Status};
use crate::fit::level::Level;
use crate::fit::params::GroupParams;
use crate::fit::schedule;
use crate::io::image::Image;
use crate::math::sampler::hash_seed;
use crate::math::Rgb;
use crate::photo::Photo;
use crate::prepare::openness::{open_scene_warning, OPEN_SCENE};
use crate::prepare::UsableMask;
use crate::render::film::{render, RenderOptions};
use crate::scene::atlas::Atlas;
use crate::scene::texture::{Mapping, Texture};
use crate::scene::Scene;
use std::sync::Arc;
use std::time::Instant;

/// The cached pixels of every group at one pixel budget: (pixels, their tiles, tile count).
pub(super) type PixelLists = Vec<(Vec<usize>, Vec<u32>, usize)>;

/// A further photo's part of a recovery (`views.rs`).
pub(super) struct ViewRun<'a> {
    pub(super) name: String,
    pub(super) scene: &'a Scene,
    pub(super) photo: &'a Photo,
    pub(super) mask: UsableMask,
    /// The view's scene with every group's current parameters.
    pub(super) current: Scene,
    pub(super) pixel_lists: PixelLists,
}

/// A recovery in progress.
pub struct RecoveryLoop<'a> {
    pub(super) scene: &'a Scene,
    pub(super) photo: &'a Photo,
    pub(super) mask: UsableMask,
    pub(super) opts: &'a RecoverOptions,
    pub(super) states: Vec<GroupState>,
    /// The scene with every group's current parameters.
    pub(super) current: Scene,
    /// Whether the previous iteration left the scene nearly unchanged ([`schedule::settled`]).
    pub(super) settled: bool,
    /// The next global iteration to run.
    pub(super) next: u32,
    /// Global iterations run, in this call and before the checkpoint resumed from.
    pub(super) iterations: u32,
    pub(super) cache_builds: u32,
    pub(super) evals: u64,
    pub(super) converged: bool,
    t0: Instant,
    /// Time before this run: that of the interrupted run, when resuming.
    pub(super) elapsed_before: f64,
    pub(super) cap: usize,
    pub(super) pixel_lists: PixelLists,
    /// The unseen groups' recent estimates and the last ones (`unseen::update`).
    pub(super) unseen_history: crate::fit::unseen::History,
    pub(super) unseen: Vec<crate::fit::unseen::UnseenEstimate>,
    /// The stray light's last estimate (`RecoverOptions::stray_light`).
    pub(super) stray: Option<crate::fit::stray::StrayEstimate>,
    /// Per group, the atlas a texture of it would use (fitted groups only; `texture.rs`).
    pub(super) atlases: Vec<Option<Arc<Atlas>>>,
    /// Per group at level 7, its current texture as the renderer reads it.
    pub(super) textures: Vec<Option<Arc<Texture>>>,
    /// Per group, the pixels a texture of it is fitted from (`texture_pixels`), found when a
    /// group first needs them.
    pub(super) texture_pixels: std::cell::OnceCell<Vec<Vec<usize>>>,
    /// The scene's index buffers in the first photo, found when first needed.
    pub(super) index_buffers: std::cell::OnceCell<crate::render::aov::IndexBuffers>,
    /// The further photos fitted with the first (`views.rs`); empty for one photo.
    pub(super) extra: Vec<ViewRun<'a>>,
    /// Per photo (the first included), its exposure factor: all 1 for one photo.
    pub(super) exposures: Vec<f32>,
    /// Per photo, the residual and pixel count of the last iteration (several photos only).
    pub(super) residuals: Vec<(f32, usize)>,
    /// The first photo divided by `exposures[0]` when that is not 1 (§5.1's pseudo-textures
    /// read it), made when first needed.
    pub(super) photo_scaled: std::cell::OnceCell<Vec<Rgb>>,
}

/// The pixels a textured group is fitted from: its usable pixels, those the mask's edge test
/// removed and the pure pixels of the band. Near a group's boundary a strong photo edge is taken
/// for the neighbour's surface showing through a misregistered model, and the band guards
/// against the same; on a textured group the edges are mostly the texture's own strokes (a
/// poster's dark band and its lettering next to its frame, a book spine's label), and the band
/// hides the texels along the outline (a book spine's margins), which could then only be
/// guessed. The model is registered to the photo before masking (`prepare/register.rs`), so a
/// pixel the object covers wholly (`prepare/coverage.rs`) sees that object in the photo too;
/// pixels that mix two objects stay out.
fn texture_pixels(
    scene: &Scene,
    mask: &UsableMask,
    ib: &crate::render::aov::IndexBuffers,
) -> Vec<Vec<usize>> {
    use crate::prepare::mask::Reject;
    let pure = crate::prepare::coverage::pure_pixels(scene, &scene.camera, ib);
    let mut out = vec![Vec::new(); scene.groups.len()];
    for (i, (&g, r)) in mask.group.iter().zip(&mask.reason).enumerate() {
        let g = match r {
            Reject::None => g,
            Reject::Edge => ib.group.get(i).copied().unwrap_or(-1),
            Reject::Band if pure.get(i) == Some(&true) => ib.group.get(i).copied().unwrap_or(-1),
            _ => -1,
        };
        if g >= 0 {
            if let Some(v) = out.get_mut(g as usize) {
                v.push(i);
            }
        }
    }
    out
}

/// The per-channel factor that brings the photo's image of a group in a mirror (already
/// divided by the mirror's ρs) to the model's mean over the same pixels, and whether the
/// pixels are to be used: not where the two disagree by more than [`MIRROR_SCALE_LIMIT`] (the
/// mirror's image is then not that group's, or the mirror not what it was fitted as).
///
/// The mirror's image determines the product of its ρs and the group's reflectance only: the
/// mirror's ρs is fitted from the same pixels against the group's current render, so their
/// overall level says nothing new about the group and would only drag it towards its last
/// value. What they add is the pattern, seen a second time from another direction; the level
/// is left to the group's own pixels.
pub(super) fn mirror_scale(cache: &crate::fit::cache::GroupCache, model: &[Rgb]) -> (Rgb, bool) {
    let (photo, model) = cache
        .pixels
        .iter()
        .zip(model)
        .fold((Rgb::ZERO, Rgb::ZERO), |(a, b), (p, m)| {
            (a + p.photo, b + *m)
        });
    let scale = model / photo;
    let ok = (0..3).all(|c| {
        scale[c].is_finite() && (1.0 / MIRROR_SCALE_LIMIT..=MIRROR_SCALE_LIMIT).contains(&scale[c])
    });
    (scale, ok)
}

/// How far (as a factor) the photo's image of a group in a mirror may be from the model's for
/// those pixels to be used ([`mirror_scale`]).
pub const MIRROR_SCALE_LIMIT: f32 = 1.25;

/// A textured group's cache draws this many times the samples per pixel: its texels are fitted
/// from a few pixels each, not from the whole group, so their noise is that of single pixels.
pub const TEXTURED_SAMPLES: u32 = 4;

/// A group at a GGX level (8, 9, 10) draws `ggx_samples(α)` times the samples per pixel. A coat's
/// lobe is weak (ρs ≈ 0.04 over a bright base) and its width is decided by a small part of the
/// signal, so the cache's noise in the specular term biases it narrow (minimising the cost over
/// ρ divides by the noisy Σ s₀s₁, and a narrower lobe's is noisier), the more so the narrower
/// the lobe: 4× at α 0.1 and above, growing as 1/α to 16× at α 0.025 and below.
pub fn ggx_samples(alpha: f32) -> u32 {
    (0.4 / alpha.max(1e-3)).round().clamp(4.0, 16.0) as u32
}

/// A group at a microfacet level (8 or 10) draws this many times more indirect samples again.
/// A metal's radiance is mostly its lobe's reflection of the room, which only the indirect
/// samples see (the light samples see the light's highlight), and with fewer their noise moves
/// its fit along the ρd–ρs–α ridge from one global iteration to the next.
pub const METAL_INDIRECT: u32 = 4;

impl<'a> RecoveryLoop<'a> {
    /// A fresh recovery: every fitted group starts at level 1 with grey parameters.
    pub fn start(
        scene: &'a Scene,
        photo: &'a Photo,
        mask: &UsableMask,
        views: &[PhotoView<'a>],
        opts: &'a RecoverOptions,
    ) -> RecoveryLoop<'a> {
        let states = initial_states(scene, &merged_mask(mask, views), opts);
        Self::with_states(scene, photo, mask, views, opts, states, 0)
    }

    /// The recovery that wrote `c`, continued after its last iteration. Fails if the checkpoint
    /// holds parameters no fit could have produced.
    pub fn resume(
        scene: &'a Scene,
        photo: &'a Photo,
        mask: &UsableMask,
        views: &[PhotoView<'a>],
        opts: &'a RecoverOptions,
        c: &Checkpoint,
    ) -> Result<RecoveryLoop<'a>, RecoverError> {
        if let Some(s) = c.implausible_group() {
            return Err(RecoverError::ImplausibleCheckpoint {
                group: s.name.clone(),
                params: s.params,
            });
        }
        let mut r = Self::with_states(
            scene,
            photo,
            mask,
            views,
            opts,
            c.states.clone(),
            c.next_iteration,
        );
        if c.exposures.len() == r.exposures.len() {
            r.exposures = c.exposures.clone();
        }
        r.elapsed_before = c.elapsed;
        r.settled = c.settled;
        r.cache_builds = c.cache_builds;
        r.evals = c.objective_evals;
        r.iterations = c.next_iteration;
        r.converged = c.next_iteration >= opts.max_iterations;
        r.unseen_history = c.unseen_history.clone();
        if let (Some(s), true) = (&c.stray_light, opts.stray_light) {
            r.set_stray_light(Rgb::from_array(s.radiance));
            r.stray = Some(s.clone());
        }
        Ok(r)
    }

    /// Sets the stray light of the scene of every photo (one constant environment for all).
    pub(super) fn set_stray_light(&mut self, v: Rgb) {
        self.current.stray_light = v;
        for e in self.extra.iter_mut() {
            e.current.stray_light = v;
        }
    }

    fn with_states(
        scene: &'a Scene,
        photo: &'a Photo,
        mask: &UsableMask,
        views: &[PhotoView<'a>],
        opts: &'a RecoverOptions,
        states: Vec<GroupState>,
        next: u32,
    ) -> RecoveryLoop<'a> {
        let by_group = mask.pixels_by_group(scene.groups.len());
        let atlases: Vec<Option<Arc<Atlas>>> = (0..scene.groups.len())
            .map(|g| {
                if !states[g].is_fitted() {
                    return None;
                }
                let texel = crate::fit::texture::footprint(scene, &by_group[g])?;
                let objects = &scene.groups[g].objects;
                Some(Arc::new(Atlas::build(
                    &scene.geometry,
                    objects,
                    scene.objects.len(),
                    texel,
                )))
            })
            .collect();
        let textures: Vec<Option<Arc<Texture>>> = (0..states.len())
            .map(|g| texture_of(scene, &states[g], atlases[g].as_ref()))
            .collect();
        let mut current = scene.clone();
        apply(&mut current, &states, &textures);
        let cap = pixel_budget(opts, next);
        let extra: Vec<ViewRun> = views
            .iter()
            .map(|v| {
                let mut current = v.scene.clone();
                apply(&mut current, &states, &textures);
                ViewRun {
                    name: v.name.clone(),
                    scene: v.scene,
                    photo: v.photo,
                    mask: v.mask.clone(),
                    current,
                    pixel_lists: Vec::new(),
                }
            })
            .collect();
        let mut r = RecoveryLoop {
            scene,
            photo,
            mask: mask.clone(),
            opts,
            states,
            current,
            settled: false,
            next,
            iterations: 0,
            cache_builds: 0,
            evals: 0,
            converged: false,
            t0: Instant::now(),
            elapsed_before: 0.0,
            cap,
            pixel_lists: Vec::new(),
            unseen_history: Default::default(),
            unseen: Vec::new(),
            stray: None,
            atlases,
            textures,
            texture_pixels: std::cell::OnceCell::new(),
            index_buffers: std::cell::OnceCell::new(),
            exposures: vec![1.0; 1 + extra.len()],
            residuals: Vec::new(),
            photo_scaled: std::cell::OnceCell::new(),
            extra,
        };
        r.choose_all(cap);
        r
    }

    /// The pixels of group `g`'s image in each confirmed ideal mirror: per mirror, its ρs and
    /// its usable pixels that show `g` wholly ([`crate::fit::cache::shows_in_mirror`]).
    pub(super) fn mirror_view_pixels(&self, g: usize) -> Vec<(usize, Rgb, Vec<usize>)> {
        let ib = self.index_buffers();
        let mirrors = self.states.iter().enumerate().filter_map(|(m, s)| {
            let confirmed = m != g && s.status == Status::Confirmed;
            match s.params.material(s.level) {
                crate::scene::Material::Mirror { rho_s } if confirmed => Some((m, rho_s)),
                _ => None,
            }
        });
        mirrors
            .filter_map(|(m, rho_s)| {
                let pixels: Vec<usize> = (0..self.mask.group.len())
                    .filter(|&i| {
                        self.mask.group[i] == m as i32
                            && ib.mirror_group[i] == g as i32
                            && crate::fit::cache::shows_in_mirror(self.scene, i, m, g)
                    })
                    .collect();
                (!pixels.is_empty()).then_some((m, rho_s, pixels))
            })
            .collect()
    }

    /// The scene's index buffers through the first photo's camera, made when first needed.
    fn index_buffers(&self) -> &crate::render::aov::IndexBuffers {
        self.index_buffers
            .get_or_init(|| crate::render::aov::index_buffers(self.scene, &self.scene.camera))
    }

    /// After a textured group's cache: re-asks Algorithm 1's gate of it when a group that now
    /// lights it has changed level since its texture ([`schedule::texture_sources_changed`]);
    /// the trigger when a group changes level reads the textured group's shares from before.
    pub(super) fn note_texture_sources(&mut self, g: usize) {
        if self.states[g].level != Level::Textured {
            self.states[g].texture_sources.clear();
            return;
        }
        let levels: Vec<Level> = self.states.iter().map(|s| s.level).collect();
        let st = &mut self.states[g];
        if schedule::texture_sources_changed(&st.texture_sources, &st.lit_by, &levels) {
            st.recheck_texture = true;
            st.texture_sources = levels;
        } else if st.texture_sources.len() != levels.len() {
            st.texture_sources = levels;
        }
    }

    /// Per group, the pixels a texture of it is fitted from ([`texture_pixels`]).
    pub(super) fn texture_pixels(&self) -> &[Vec<usize>] {
        self.texture_pixels
            .get_or_init(|| texture_pixels(self.scene, &self.mask, self.index_buffers()))
    }

    /// How many groups each global iteration fits.
    pub fn fitted_groups(&self) -> usize {
        self.states.iter().filter(|s| s.is_fitted()).count()
    }

    /// The next global iteration to run.
    pub fn next_iteration(&self) -> u32 {
        self.next
    }

    /// Whether the loop is done: every group's level decided and averaged, nothing moving, the
    /// full pixel budget reached; or the iteration limit reached.
    pub fn converged(&self) -> bool {
        self.converged || self.next >= self.opts.max_iterations
    }

    /// The log line of `event` for group `g` in global iteration `it`, with the group's
    /// parameters as they are now.
    pub(super) fn line(&self, it: u32, g: usize, event: Event, seconds: f64) -> LogLine {
        let st = &self.states[g];
        LogLine {
            iteration: it,
            group: st.name.clone(),
            params: st.params.named(st.params_level()).into_iter().collect(),
            distribution: st
                .params_level()
                .has_distribution()
                .then(|| st.params.distribution.name()),
            event,
            seconds,
            cache_seconds: None,
            elapsed: self.elapsed(),
        }
    }

    /// Seconds since the recovery started (across a resume, the interrupted run's included).
    pub(super) fn elapsed(&self) -> f64 {
        self.elapsed_before + self.t0.elapsed().as_secs_f64()
    }

    /// Chooses the pixels of every group's cache, in every photo, at a given pixel budget.
    pub(super) fn choose_all(&mut self, cap: usize) {
        let cache_opts = CacheOptions {
            max_pixels: cap,
            ..self.opts.cache.clone()
        };
        let w = self.scene.camera.width as usize;
        let n = self.scene.groups.len();
        let usable = self.mask.pixels_by_group(n);
        self.pixel_lists = (0..n)
            .map(|g| self.choose(g, &cache_opts, w, &usable[g]))
            .collect();
        for k in 0..self.extra.len() {
            let usable = self.extra[k].mask.pixels_by_group(n);
            let lists = (0..n)
                .map(|g| self.choose_in_view(k, g, &cache_opts, &usable[g]))
                .collect();
            self.extra[k].pixel_lists = lists;
        }
    }

    /// The cached pixels of group `g` in further photo `k`: a subsample of its usable pixels
    /// there (`usable`) within the budget, all of them at level 7.
    pub(super) fn choose_in_view(
        &self,
        k: usize,
        g: usize,
        cache_opts: &CacheOptions,
        usable: &[usize],
    ) -> (Vec<usize>, Vec<u32>, usize) {
        let v = &self.extra[k];
        let opts = CacheOptions {
            max_pixels: if self.states[g].level == Level::Textured {
                usize::MAX
            } else {
                cache_opts.max_pixels
            },
            ..cache_opts.clone()
        };
        choose_pixels(usable, v.scene.camera.width as usize, &opts)
    }

    /// The cached pixels of group `g`: at level 7 all of [`texture_pixels`] (every texel needs
    /// its pixels), else a subsample of its usable ones (`usable`) within the budget.
    pub(super) fn choose(
        &self,
        g: usize,
        cache_opts: &CacheOptions,
        w: usize,
        usable: &[usize],
    ) -> (Vec<usize>, Vec<u32>, usize) {
        let all = CacheOptions {
            max_pixels: usize::MAX,
            ..cache_opts.clone()
        };
        if self.states[g].level == Level::Textured {
            choose_pixels(&self.texture_pixels()[g], w, &all)
        } else {
            choose_pixels(usable, w, cache_opts)
        }
    }

    /// Ends the analysis of every group still analysing once the iterations are over: each keeps
    /// the best level it found, and `log` receives a `decided` event saying why it had not
    /// decided earlier (`GroupState::decide_at_end`). A run always ends with every group decided.
    pub fn decide_the_undecided(&mut self, log: &mut dyn FnMut(&LogLine)) {
        let (opts, iterations) = (self.opts, self.iterations);
        for g in 0..self.states.len() {
            if let Some(event) = self.states[g].decide_at_end(&opts.hierarchy, iterations) {
                log(&self.line(iterations.saturating_sub(1), g, event, 0.0));
            }
        }
    }

    /// The state after the last iteration (its `fingerprint` and `log_bytes` are the caller's
    /// to fill).
    pub fn checkpoint(&self) -> Checkpoint {
        Checkpoint {
            version: CHECKPOINT_VERSION,
            fingerprint: 0,
            // A converged run resumes straight to its final render.
            next_iteration: if self.converged {
                self.opts.max_iterations
            } else {
                self.next
            },
            states: self.states.clone(),
            settled: self.settled,
            cache_builds: self.cache_builds,
            objective_evals: self.evals,
            log_bytes: 0,
            elapsed: self.elapsed(),
            unseen_history: self.unseen_history.clone(),
            stray_light: self.stray.clone(),
            exposures: if self.extra.is_empty() && self.exposures[0] == 1.0 {
                Vec::new()
            } else {
                self.exposures.clone()
            },
        }
    }

    /// The final render, as two half-sample images with different seeds (their mean is the
    /// synthetic image, their difference the noise floor), and each group's error on it.
    pub fn finish(self) -> Recovery {
        let opts = self.opts;
        let tf = Instant::now();
        let fit_s = tf.duration_since(self.t0).as_secs_f64();
        // An open scene assumes that nothing but its lights shines in from outside: said where
        // the user sees it, with the option that fits it instead.
        let (mut open, mut n) = (0.0f64, 0.0f64);
        for (s, st) in self.states.iter().zip(&self.mask.stats) {
            if s.is_fitted() {
                open += s.open as f64 * st.usable as f64;
                n += st.usable as f64;
            }
        }
        let open = if n > 0.0 { open / n } else { 0.0 };
        // `GroupCache::open`, weighted by usable pixels.
        if !opts.stray_light && self.current.outside_light_is_none() && open > OPEN_SCENE {
            tracing::warn!("{}", open_scene_warning(open));
        }
        let (width, height) = (self.mask.width, self.photo.image.height);
        let spp = opts
            .final_spp
            .unwrap_or_else(|| super::options::auto_final_spp(width * height));
        let half = (spp / 2).max(1);
        let tile = block_side(2 * half);
        let render_half = |seed: u64| {
            render(
                &self.current,
                &self.current.camera,
                &RenderOptions {
                    spp: half,
                    seed: hash_seed(&[opts.seed, seed]),
                    progress: opts.progress,
                },
            )
        };
        let a = render_half(101);
        let b = render_half(202);
        let final_render_s = tf.elapsed().as_secs_f64();
        let mut synthetic = a.clone();
        for (s, bb) in synthetic.data.iter_mut().zip(&b.data) {
            *s = 0.5 * (*s + *bb);
        }
        // The first photo against the render scaled by its exposure factor (1 for one photo).
        let e0 = self.exposures[0];
        let scaled = |im: &Image| {
            let mut im = im.clone();
            im.data.iter_mut().for_each(|c| *c *= e0);
            im
        };
        let (syn_e, a_e, b_e) = if e0 != 1.0 {
            (scaled(&synthetic), scaled(&a), scaled(&b))
        } else {
            (synthetic.clone(), a.clone(), b.clone())
        };
        let final_error: Vec<Option<(f32, f32)>> = self
            .mask
            .pixels_by_group(self.states.len())
            .iter()
            .map(|px| image_error(width, tile, px, &syn_e, &a_e, &b_e, &self.photo.image))
            .collect();
        let views = if self.extra.is_empty() {
            Vec::new()
        } else {
            let first = match self.scene.view {
                Some(k) => self.scene.views[k].name.clone(),
                None => "photo 1".to_string(),
            };
            std::iter::once(first)
                .chain(self.extra.iter().map(|v| v.name.clone()))
                .enumerate()
                .map(|(k, name)| {
                    let (residual, pixels) = self.residuals.get(k).copied().unwrap_or_default();
                    ViewFit {
                        name,
                        exposure: self.exposures[k],
                        residual,
                        pixels,
                    }
                })
                .collect()
        };
        let total_s = self.t0.elapsed().as_secs_f64();
        let mut states = self.states;
        // How far the light each group sends the others, and its own reflectances, can be
        // trusted: a fitted group's model as far as its photo shows, an unseen one's
        // reflectance as far as it is known.
        use crate::fit::uncertainty::{
            cache_misfit, model_misfit, unseen_misfit, with_neighbours, with_own_misfit,
        };
        let mut misfit: Vec<f32> = (states.iter().zip(&final_error))
            .map(|(st, e)| match (st.is_fitted(), e) {
                (true, Some((error, noise))) => model_misfit(*error, *noise)
                    .max(cache_misfit(st.error, st.noise_floor, st.photo_noise)),
                _ => 0.0,
            })
            .collect();
        for u in &self.unseen {
            if let Some(m) = misfit.get_mut(u.group) {
                *m = unseen_misfit(u.rho_d, u.sigma);
            }
        }
        for (g, st) in states.iter_mut().enumerate() {
            let own = if st.is_fitted() { misfit[g] } else { 0.0 };
            if let Some(sd) = st.sigma.as_mut() {
                let wide = with_neighbours(sd, &st.params, g, &st.lit_by, &misfit);
                *sd = with_own_misfit(&wide, &st.params, own);
            }
        }
        for st in states.iter_mut().filter(|s| s.is_fitted()) {
            let weak = st.sigma.as_ref().and_then(|sd| {
                crate::fit::uncertainty::weak_lobe(st.params_level(), &st.params, sd)
            });
            if let Some(w) = weak {
                st.note = Some(match st.note.take() {
                    Some(n) => format!("{n}; {w}"),
                    None => w,
                });
            }
        }
        Recovery {
            groups: states,
            pixel_stats: self.mask.stats.clone(),
            unseen: self.unseen,
            stray_light: self.stray,
            scene: self.current,
            synthetic,
            final_error,
            mask: self.mask,
            iterations: self.iterations,
            cache_builds: self.cache_builds,
            objective_evals: self.evals,
            total_s,
            fit_s,
            final_render_s,
            final_spp: 2 * half,
            error_tile: tile,
            views,
            exposure_factor: e0,
        }
    }

    /// The first photo divided by its exposure factor, as the caches hold it.
    pub(super) fn photo_in_cache_units(&self) -> &[Rgb] {
        let e0 = self.exposures[0];
        if e0 == 1.0 {
            return &self.photo.image.data;
        }
        self.photo_scaled
            .get_or_init(|| self.photo.image.data.iter().map(|&c| c / e0).collect())
    }
}

/// The factor photo / rendering over the grey card's usable pixels, the card at its known ρ and
/// every other group with its current materials (`photo::exposure::from_grey_card`).
pub(super) fn grey_card_factor(
    current: &Scene,
    photo: &Photo,
    mask: &UsableMask,
    card: &super::options::GreyCard,
) -> Result<f32, String> {
    crate::prepare::exposure::from_grey_card(current, photo, mask, &card.group, card.rho, 4096)
        .map(|c| c.factor)
}

/// Every group's state before the first iteration: lights and fixed groups keep their
/// materials, groups with no usable pixels get the default diffuse reflectance, the rest are
/// analysed from grey.
/// The first photo's mask with the further photos' usable pixels counted in its statistics: a
/// group is fitted if any photo shows it.
fn merged_mask(mask: &UsableMask, views: &[PhotoView]) -> UsableMask {
    let mut m = mask.clone();
    for v in views {
        for (a, b) in m.stats.iter_mut().zip(&v.mask.stats) {
            a.usable += b.usable;
            a.visible += b.visible;
        }
    }
    m
}

fn initial_states(scene: &Scene, mask: &UsableMask, opts: &RecoverOptions) -> Vec<GroupState> {
    scene
        .groups
        .iter()
        .enumerate()
        .map(|(g, grp)| {
            let objs: Vec<_> = grp.objects.iter().map(|&o| &scene.objects[o]).collect();
            if objs.iter().all(|o| o.is_emitter()) {
                GroupState::new(
                    &grp.name,
                    Status::Light,
                    GroupParams::from_material(&objs[0].material),
                )
            } else if grp.fixed {
                GroupState::new(
                    &grp.name,
                    Status::Fixed,
                    GroupParams::from_material(&objs[0].material),
                )
            } else if mask.stats[g].usable == 0 && opts.unseen.enabled {
                // Grey until the first estimate, after global iteration 0 (unseen.rs).
                let mut s = GroupState::new(&grp.name, Status::Default, GroupParams::default());
                s.note = Some(format!(
                    "no usable pixels ({} visible): its ρd is estimated from the light it \
                     reflects onto the seen groups (the seen groups' mean albedo where the photo \
                     does not determine it; --white-unseen gives it white)",
                    mask.stats[g].visible
                ));
                tracing::warn!("group '{}': {}", grp.name, s.note.as_ref().unwrap());
                s
            } else if mask.stats[g].usable == 0 {
                let mut s = GroupState::new(
                    &grp.name,
                    Status::Default,
                    GroupParams {
                        rho_d: Rgb::splat(opts.default_rho_d),
                        ..Default::default()
                    },
                );
                s.note = Some(format!(
                    "no usable pixels ({} visible): given the default diffuse reflectance {}",
                    mask.stats[g].visible, opts.default_rho_d
                ));
                tracing::warn!("group '{}': {}", grp.name, s.note.as_ref().unwrap());
                s
            } else {
                GroupState::new(&grp.name, Status::Analysing, GroupParams::default())
            }
        })
        .collect()
}

/// Applies each group's current parameters (and texture) to its objects.
pub(super) fn apply(scene: &mut Scene, states: &[GroupState], textures: &[Option<Arc<Texture>>]) {
    for obj in scene.objects.iter_mut() {
        let st = &states[obj.group];
        if matches!(
            st.status,
            Status::Analysing | Status::Confirmed | Status::Default
        ) {
            obj.material = match &textures[obj.group] {
                Some(t) if st.level == Level::Textured => {
                    st.params.textured(t.clone(), st.params_level())
                }
                _ => st.params.material(st.level),
            };
        }
    }
}

/// The texture the renderer reads for a group at level 7 (None at the other levels).
pub(super) fn texture_of(
    scene: &Scene,
    st: &GroupState,
    atlas: Option<&Arc<Atlas>>,
) -> Option<Arc<Texture>> {
    let (t, atlas) = (st.texture.as_ref()?, atlas?);
    if st.level != Level::Textured || t.texels.len() != atlas.width * atlas.height {
        return None;
    }
    let g = scene.group_index(&st.name)?;
    Some(Arc::new(Texture {
        width: t.width,
        height: t.height,
        texels: t.texels.clone(),
        path: std::path::PathBuf::from(format!("textures/{}.exr", texture_stem(g, &st.name))),
        mapping: Mapping::Atlas(atlas.clone()),
    }))
}

/// A file name for group `g`'s texture: its name where that is a safe file name, else its index.
pub fn texture_stem(g: usize, name: &str) -> String {
    let safe = !name.is_empty()
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_');
    if safe {
        name.to_string()
    } else {
        format!("group{g}")
    }
}

/// ε of one group between a rendered image and the photo over its usable pixels `pixels`
/// (row-major indices in an image `width` wide), on `side`-pixel square tiles, and the noise
/// floor from the two half renders `a`, `b`. Only the group's own tiles are summed, in the
/// order of their index in the image: the same sums as over all of the image's tiles (the
/// others are zero) without a pass over the image per group.
pub fn image_error(
    width: usize,
    side: usize,
    pixels: &[usize],
    syn: &Image,
    a: &Image,
    b: &Image,
    photo: &Image,
) -> Option<(f32, f32)> {
    let tile: Vec<usize> = pixels.iter().map(|&i| block_tile(i, width, side)).collect();
    let mut tiles = tile.clone();
    tiles.sort_unstable();
    tiles.dedup();
    let terms = pixels.iter().zip(&tile).map(|(&i, t)| {
        let terms = PixelTerms {
            syn: syn.data[i],
            photo: photo.data[i],
            halves: [a.data[i], b.data[i]],
        };
        (tiles.binary_search(t).unwrap_or(0), terms)
    });
    tiled_error(tiles.len(), terms).map(|e| (e.error, e.noise_floor))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::error::block_tiles;

    /// `image_error` over a group's own tiles is, to the bit, the sum over all of the image's
    /// tiles it replaces (one pass over the image per group).
    #[test]
    fn image_error_on_the_groups_tiles_is_that_on_all_tiles() {
        let (w, h) = (23, 13);
        let img = |k: u32| {
            let mut im = Image::new(w, h);
            for (i, c) in im.data.iter_mut().enumerate() {
                let v = (mix(i as u32 * 7 + k) % 1000) as f32 / 997.0;
                *c = Rgb::new(v, 0.5 * v + 0.1, 1.0 - 0.3 * v);
            }
            im
        };
        let (syn, a, b, photo) = (img(1), img(2), img(3), img(4));
        // Two groups interleaved in irregular runs, so their tiles are not visited in order.
        let group: Vec<i32> = (0..w * h).map(|i| (mix(i as u32) % 3) as i32 - 1).collect();
        for (g, side) in [(0, 4), (1, 4), (0, 8)] {
            let px: Vec<usize> = (0..w * h).filter(|&i| group[i] == g).collect();
            let all = px.iter().map(|&i| {
                let t = PixelTerms {
                    syn: syn.data[i],
                    photo: photo.data[i],
                    halves: [a.data[i], b.data[i]],
                };
                (block_tile(i, w, side), t)
            });
            let reference =
                tiled_error(block_tiles(w, h, side), all).map(|e| (e.error, e.noise_floor));
            assert!(reference.is_some());
            assert_eq!(image_error(w, side, &px, &syn, &a, &b, &photo), reference);
        }
        assert_eq!(image_error(w, 4, &[], &syn, &a, &b, &photo), None);
    }

    fn mix(x: u32) -> u32 {
        let x = x.wrapping_mul(0x9E37_79B9) ^ (x >> 15);
        x.wrapping_mul(0x85EB_CA6B) ^ (x >> 13)
    }
}
