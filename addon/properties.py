"""DRT settings stored in the .blend: one PropertyGroup on the scene, ``scene.drt``.

Defaults equal Cycles's (bounces 12/4/4/12, no clamping, Blackman-Harris filter), so a scene
set up for Cycles converges to the same image. Camera depth of field and motion blur use
Blender's own properties (``camera.data.dof``, ``scene.render.motion_blur_*``), not copies here.
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty, StringProperty

SAMPLER_ITEMS = (
    ("SOBOL", "Sobol", "Owen-scrambled Sobol sequence (like Cycles's tabulated Sobol)", 0),
    ("STRATIFIED", "Stratified", "Jittered stratified samples per dimension", 1),
    ("RANDOM", "Random", "Independent uniform random samples (for testing)", 2),
)

FILTER_ITEMS = (
    ("BLACKMAN_HARRIS", "Blackman-Harris", "Blackman-Harris filter (Cycles's default)", 0),
    ("GAUSSIAN", "Gaussian", "Gaussian filter", 1),
    ("BOX", "Box", "Box filter", 2),
)

# Cycles's enums (cycles/properties.py), same ids, names and values
DENOISING_PREFILTER_ITEMS = (
    ("NONE", "None", "No prefiltering, use when guiding passes are noise-free", 1),
    ("FAST", "Fast", "Denoise color and guiding passes together. Improves quality when guiding "
     "passes are noisy using least amount of extra processing time", 2),
    ("ACCURATE", "Accurate", "Prefilter noisy guiding passes before denoising color. Improves "
     "quality when guiding passes are noisy using extra processing time", 3),
)
DENOISING_QUALITY_ITEMS = (
    ("HIGH", "High", "High quality", 1),
    ("BALANCED", "Balanced", "Balanced between performance and quality", 2),
    ("FAST", "Fast", "High performance", 3),
)
DENOISING_INPUT_ITEMS = (
    ("RGB", "None", "Don't use utility passes for denoising", 1),
    ("RGB_ALBEDO", "Albedo", "Use albedo pass for denoising", 2),
    ("RGB_ALBEDO_NORMAL", "Albedo and Normal", "Use albedo and normal passes for denoising", 3),
)


def _tag_scene(self, context):
    """A Python property's change does not reach the depsgraph by itself: tag the scene so the
    Rendered viewport (``view_update``) sees it, as it sees Cycles's settings."""
    scene = getattr(self, "id_data", None)
    if scene is not None:
        scene.update_tag()


def _update_render_passes(self, context):
    """The Noisy Image pass follows the switch (as Cycles's does)."""
    vl = getattr(context, "view_layer", None)
    if vl is not None:
        vl.update_render_passes()


class DRTSceneSettings(bpy.types.PropertyGroup):
    samples: IntProperty(
        name="Render Samples", description="Samples per pixel for final renders",
        default=64, min=1, soft_max=4096, max=1 << 24)
    preview_samples: IntProperty(
        name="Viewport Samples", description="Samples per pixel for viewport renders",
        default=16, min=1, soft_max=1024, max=1 << 24)
    seed: IntProperty(
        name="Seed", description="Seed of the sample sequences; the same seed gives the same image",
        default=0, min=0)
    sampler: EnumProperty(
        name="Sampler", description="Random number pattern used for sampling",
        items=SAMPLER_ITEMS, default="SOBOL")

    max_bounces: IntProperty(
        name="Total", description="Maximum number of bounces, all kinds together",
        default=12, min=0, max=1024)
    diffuse_bounces: IntProperty(
        name="Diffuse", description="Maximum number of diffuse reflection bounces",
        default=4, min=0, max=1024)
    glossy_bounces: IntProperty(
        name="Glossy", description="Maximum number of glossy reflection bounces",
        default=4, min=0, max=1024)
    transmission_bounces: IntProperty(
        name="Transmission", description="Maximum number of transmission bounces",
        default=12, min=0, max=1024)
    transparent_bounces: IntProperty(
        name="Transparent", description="Maximum number of transparent surfaces (alpha, Transparent "
        "BSDF) a ray passes; they do not count as bounces (Cycles's Transparent max bounces)",
        default=8, min=0, max=1024)
    volume_bounces: IntProperty(
        name="Volume", description="Maximum number of volume scattering events beyond the first "
        "(Cycles's Volume bounces: 0 = single scattering)",
        default=0, min=0, max=1024)

    clamp_direct: FloatProperty(
        name="Direct Light", description="Clamp the radiance of direct light samples (0 disables)",
        default=0.0, min=0.0)
    clamp_indirect: FloatProperty(
        name="Indirect Light",
        description="Clamp the radiance of indirect light samples (0 disables)",
        default=0.0, min=0.0)

    filter_type: EnumProperty(
        name="Pixel Filter",
        description="Pixel filter when the Cycles add-on is disabled (its width is Blender's Filter "
                    "Size); otherwise DRT uses Cycles's Film > Pixel Filter settings",
        items=FILTER_ITEMS, default="BLACKMAN_HARRIS")

    use_sample_subset: BoolProperty(
        name="Sample Subset",
        description="Render only a range of the samples, to split one frame over several machines",
        default=False)
    sample_offset: IntProperty(
        name="Offset", description="Index of the first sample rendered", default=0, min=0)
    sample_count: IntProperty(
        name="Length", description="Number of samples rendered (0: up to the sample count)",
        default=0, min=0)

    # denoising: Cycles's controls (same ids and defaults except the switch, off: DRT stays an
    # unbiased renderer unless asked); per view layer, Cycles's use_denoising and Denoising Data
    use_denoising: BoolProperty(
        name="Denoise", description="Denoise the final render with Open Image Denoise "
        "(albedo and normal guides); the noisy image is kept in the Noisy Image pass",
        default=False, update=_update_render_passes)
    denoising_prefilter: EnumProperty(
        name="Prefilter", description="Prefilter noisy guiding (albedo and normal) passes to "
        "improve denoising quality", items=DENOISING_PREFILTER_ITEMS, default="ACCURATE")
    denoising_quality: EnumProperty(
        name="Quality", description="Overall denoising quality",
        items=DENOISING_QUALITY_ITEMS, default="HIGH")
    denoising_input_passes: EnumProperty(
        name="Passes", description="Passes used by the denoiser to distinguish noise from shader "
        "and geometry detail", items=DENOISING_INPUT_ITEMS, default="RGB_ALBEDO_NORMAL")

    # viewport denoising: Cycles's Sampling > Viewport > Denoise (same ids and defaults except
    # the switch, off as for final renders)
    use_preview_denoising: BoolProperty(
        name="Viewport Denoise", description="Denoise the Rendered viewport with Open Image Denoise",
        default=False, update=_tag_scene)
    preview_denoising_start_sample: IntProperty(
        name="Start Sample", description="Sample to start denoising the viewport at",
        default=1, min=0, soft_max=1 << 12, update=_tag_scene)
    preview_denoising_prefilter: EnumProperty(
        name="Prefilter", description="Prefilter noisy guiding (albedo and normal) passes to "
        "improve denoising quality", items=DENOISING_PREFILTER_ITEMS, default="FAST", update=_tag_scene)
    preview_denoising_quality: EnumProperty(
        name="Quality", description="Overall denoising quality",
        items=DENOISING_QUALITY_ITEMS, default="BALANCED", update=_tag_scene)
    preview_denoising_input_passes: EnumProperty(
        name="Passes", description="Passes used by the denoiser to distinguish noise from shader "
        "and geometry detail", items=DENOISING_INPUT_ITEMS, default="RGB_ALBEDO", update=_tag_scene)

    # render on a Dask cluster (docs/farm.md); empty address: this machine
    cluster_address: StringProperty(
        name="Scheduler",
        description="Dask scheduler to render on, tcp://HOST:PORT or tls://HOST:PORT (empty: this "
                    "machine). The cluster runs code sent by this Blender: use only clusters you trust",
        default="")
    cluster_timeout: FloatProperty(
        name="Time-out (s)", description="Give up when the scheduler does not answer, or the cluster "
                                         "has no worker, for this many seconds",
        default=30.0, min=1.0, max=86400.0)
    cluster_tls_ca_file: StringProperty(
        name="CA Certificate", description="Certificate of the authority that signed the scheduler's (tls://)",
        default="", subtype="FILE_PATH")
    cluster_tls_cert: StringProperty(
        name="Certificate", description="This client's certificate (tls://)", default="", subtype="FILE_PATH")
    cluster_tls_key: StringProperty(
        name="Key", description="This client's private key, if not in the certificate file (tls://)",
        default="", subtype="FILE_PATH")

    @classmethod
    def register(cls):
        bpy.types.Scene.drt = PointerProperty(
            name="DRT Render Settings", description="DRT render settings", type=cls)

    @classmethod
    def unregister(cls):
        del bpy.types.Scene.drt


classes = (DRTSceneSettings,)
