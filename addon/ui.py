"""DRT's render-property panels, and Blender's built-in panels re-used through COMPAT_ENGINES.

The motion-blur and depth-of-field controls edit Blender's own properties
(``scene.render.motion_blur_*``, ``camera.data.dof``), so a scene moves between engines
unchanged.
"""

import bpy

ENGINE = "DRT"

# Built-in panels shown for DRT besides those that show for BLENDER_RENDER (output, format,
# dimensions, color management, ...).
EXTRA_PANELS = (
    "DATA_PT_camera_dof", "DATA_PT_camera_dof_aperture",
    "DATA_PT_EEVEE_light", "DATA_PT_area", "DATA_PT_spot", "DATA_PT_sunlight",
    "EEVEE_MATERIAL_PT_context_material", "EEVEE_MATERIAL_PT_surface", "MATERIAL_PT_preview",
    "EEVEE_WORLD_PT_surface", "WORLD_PT_context_world",
    "EEVEE_WORLD_PT_mist",  # (World > Mist Pass: the Mist pass's start, depth and falloff)
    "RENDER_PT_color_management", "RENDER_PT_format", "RENDER_PT_frame_range",
    "VIEWLAYER_PT_layer_passes",
    "VIEWLAYER_PT_layer_passes_cryptomatte",  # (Object / Material / Asset, Levels)
)
# Panels that show for BLENDER_RENDER but draw settings DRT ignores.
SKIP_PANELS = {"RENDER_PT_simplify", "RENDER_PT_freestyle",
               "DATA_PT_light"}  # only the type row; DATA_PT_EEVEE_light draws it all

_added: list = []  # panel classes we added 'DRT' to, to undo on unregister


class DRTRenderPanel:
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES


class DRT_RENDER_PT_sampling(DRTRenderPanel, bpy.types.Panel):
    bl_label = "Sampling"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        d = context.scene.drt
        col = layout.column(align=True)
        col.prop(d, "samples", text="Render")
        col.prop(d, "preview_samples", text="Viewport")
        col = layout.column()
        col.prop(d, "sampler")
        col.prop(d, "seed")


class DRT_RENDER_PT_sampling_subset(DRTRenderPanel, bpy.types.Panel):
    bl_label = "Sample Subset"
    bl_parent_id = "DRT_RENDER_PT_sampling"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.drt, "use_sample_subset", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        d = context.scene.drt
        col = layout.column(align=True)
        col.active = d.use_sample_subset
        col.prop(d, "sample_offset")
        col.prop(d, "sample_count")


class _DenoisePanel(DRTRenderPanel):
    """Cycles's Denoise sub-panel of Sampling; ``prefix`` selects the final-render settings
    ("denoising_", switch "use_denoising") or the viewport's ("preview_denoising_")."""
    bl_parent_id = "DRT_RENDER_PT_sampling"
    bl_options = {"DEFAULT_CLOSED"}
    prefix = "denoising_"
    switch = "use_denoising"
    extra = ()

    def draw_header(self, context):
        self.layout.prop(context.scene.drt, self.switch, text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        d = context.scene.drt
        on = getattr(d, self.switch)
        col = layout.column()
        col.active = on
        col.prop(d, self.prefix + "input_passes")
        sub = col.column()
        sub.active = on and getattr(d, self.prefix + "input_passes") != "RGB"
        sub.prop(d, self.prefix + "prefilter")
        col.prop(d, self.prefix + "quality")
        for name in self.extra:
            col.prop(d, self.prefix + name)


class DRT_RENDER_PT_sampling_denoise(_DenoisePanel, bpy.types.Panel):
    """Cycles's Sampling > Render > Denoise, for DRT's final renders (Open Image Denoise)."""
    bl_label = "Denoise"


class DRT_RENDER_PT_sampling_viewport_denoise(_DenoisePanel, bpy.types.Panel):
    """Cycles's Sampling > Viewport > Denoise, for DRT's Rendered viewport."""
    bl_label = "Viewport Denoise"
    prefix = "preview_denoising_"
    switch = "use_preview_denoising"
    extra = ("start_sample",)


class DRT_VIEWLAYER_PT_passes_data(bpy.types.Panel):
    """The passes DRT fills, and Cycles's per-layer Denoising / Denoising Data settings."""
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"
    bl_context = "view_layer"
    bl_label = "Data"
    bl_parent_id = "VIEWLAYER_PT_layer_passes"
    COMPAT_ENGINES = {ENGINE}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        vl = context.view_layer
        col = layout.column(heading="Include", align=True)
        col.prop(vl, "use_pass_combined")
        col.prop(vl, "use_pass_z")
        col.prop(vl, "use_pass_normal")
        col.prop(vl, "use_pass_diffuse_color", text="Albedo (Diffuse Color)")
        col.prop(vl, "use_pass_mist")
        col.prop(vl, "use_pass_position")
        col.prop(vl, "use_pass_uv")
        col = layout.column(heading="Indexes", align=True)
        col.prop(vl, "use_pass_object_index")
        col.prop(vl, "use_pass_material_index")
        layout.prop(vl, "pass_alpha_threshold")
        col = layout.column(heading="Light", align=True)
        col.prop(vl, "use_pass_emit", text="Emission")
        col.prop(vl, "use_pass_environment")
        col.prop(vl, "use_pass_ambient_occlusion", text="Ambient Occlusion")
        cl = getattr(vl, "cycles", None)  # the Cycles add-on's view-layer settings, if enabled
        if cl is not None:
            col.prop(cl, "denoising_store_passes", text="Denoising Data")
            col = layout.column(heading="Denoise")
            col.active = context.scene.drt.use_denoising
            col.prop(cl, "use_denoising", text="This View Layer")


class DRT_RENDER_PT_light_paths(DRTRenderPanel, bpy.types.Panel):
    bl_label = "Light Paths"

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        d = context.scene.drt
        col = layout.column(align=True, heading="Max Bounces")
        col.prop(d, "max_bounces")
        col.prop(d, "diffuse_bounces")
        col.prop(d, "glossy_bounces")
        col.prop(d, "transmission_bounces")
        col.prop(d, "volume_bounces")
        col.prop(d, "transparent_bounces")
        col = layout.column(align=True, heading="Clamping")
        col.prop(d, "clamp_direct")
        col.prop(d, "clamp_indirect")
        cycles = getattr(context.scene, "cycles", None)
        if cycles is not None and hasattr(cycles, "blur_glossy"):
            # Cycles's own setting (addon/export/scene_parts.filter_glossy): one .blend, one picture
            col = layout.column(heading="Caustics")
            col.prop(cycles, "blur_glossy", text="Filter Glossy")
            col.prop(cycles, "caustics_reflective", text="Reflective")
            col.prop(cycles, "caustics_refractive", text="Refractive")


class DRT_RENDER_PT_motion_blur(DRTRenderPanel, bpy.types.Panel):
    bl_label = "Motion Blur"
    bl_options = {"DEFAULT_CLOSED"}

    def draw_header(self, context):
        self.layout.prop(context.scene.render, "use_motion_blur", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        rd = context.scene.render
        col = layout.column()
        col.active = rd.use_motion_blur
        col.prop(rd, "motion_blur_position", text="Position")
        col.prop(rd, "motion_blur_shutter")


class DRT_RENDER_PT_film(DRTRenderPanel, bpy.types.Panel):
    bl_label = "Film"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        rd = context.scene.render
        col = layout.column()
        cycles = getattr(context.scene, "cycles", None)
        if cycles is not None and hasattr(cycles, "pixel_filter_type"):
            # the same settings as Cycles's Film panel: one .blend, one filter for both engines
            col.prop(cycles, "film_exposure", text="Exposure")
            col.prop(cycles, "pixel_filter_type", text="Pixel Filter")
            if cycles.pixel_filter_type != "BOX":  # (a box is one pixel wide, as in Cycles)
                col.prop(cycles, "filter_width", text="Width")
        else:
            col.prop(context.scene.drt, "filter_type")
            if context.scene.drt.filter_type != "BOX":
                col.prop(rd, "filter_size", text="Width")
        col.prop(rd, "film_transparent", text="Transparent")


class DRT_RENDER_PT_cluster(DRTRenderPanel, bpy.types.Panel):
    """Render on a Dask cluster (docs/farm.md)."""

    bl_label = "Cluster"
    bl_options = {"DEFAULT_CLOSED"}

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.use_property_decorate = False
        d = context.scene.drt
        col = layout.column()
        col.prop(d, "cluster_address")
        sub = col.column()
        sub.active = bool(d.cluster_address.strip())
        sub.prop(d, "cluster_timeout")
        tls = col.column()
        tls.active = d.cluster_address.strip().startswith("tls://")
        tls.prop(d, "cluster_tls_ca_file")
        tls.prop(d, "cluster_tls_cert")
        tls.prop(d, "cluster_tls_key")


classes = (
    DRT_RENDER_PT_sampling,
    DRT_RENDER_PT_sampling_subset,
    DRT_RENDER_PT_sampling_denoise,
    DRT_RENDER_PT_sampling_viewport_denoise,
    DRT_RENDER_PT_light_paths,
    DRT_RENDER_PT_motion_blur,
    DRT_RENDER_PT_film,
    DRT_VIEWLAYER_PT_passes_data,
    DRT_RENDER_PT_cluster,
)


def _compat_panels():
    for cls in bpy.types.Panel.__subclasses__():
        engines = getattr(cls, "COMPAT_ENGINES", None)
        if not isinstance(engines, set) or ENGINE in engines:
            continue
        name = cls.__name__
        if name in SKIP_PANELS:
            continue
        if "BLENDER_RENDER" in engines or name in EXTRA_PANELS:
            yield cls


def add_compat_engines() -> None:
    for cls in _compat_panels():
        cls.COMPAT_ENGINES.add(ENGINE)
        _added.append(cls)


def remove_compat_engines() -> None:
    while _added:
        _added.pop().COMPAT_ENGINES.discard(ENGINE)
