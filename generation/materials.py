"""Material table and the default material (and construction) of every category.

Numbers are handbook values at room temperature for the bulk material. Sources, named per row:

* ``ETB``: The Engineering ToolBox tables "Densities of Solids", "Wood Species - Densities",
  "Friction and Friction Coefficients for various Materials", "Young's Modulus - Tensile and
  Yield Strength for common Materials", "Poisson's Ratio" (engineeringtoolbox.com).
* ``CRC``: CRC Handbook of Chemistry and Physics, 97th ed., section 12 (properties of solids).
* ``MatWeb``: MatWeb material property data sheets (typical ABS, polypropylene, PET, MDF,
  flexible polyurethane foam, soda-lime glass, porcelain, natural rubber).
* ``USDA``: Wood Handbook, USDA Forest Products Laboratory, FPL-GTR-282 (2021), ch. 4 and 5.

Restitution is the coefficient of restitution of a ball of the material dropped on a rigid
floor (ranges from impact tests summarised in ETB "Coefficient of Restitution"); friction is
the material against itself or a typical household counter-surface (wood/steel), as the ETB
friction table gives it. Softness (``softness``, unitless 0..1) is the project's own scale used
to pick contact compliance: 0 = rigid, 1 = as soft as pillow filling.

Furniture is not solid wood and appliances are not solid steel: :data:`CATEGORY_MATERIAL` gives
each category a material and, where the real object is hollow, a panel (shell) thickness, so
mass comes from the panels' volume (see ``generation.physics.shell_mass_properties``).
"""

from __future__ import annotations

from dataclasses import dataclass

from scene_builder.model import DeformableSettings, Material

__all__ = [
    "MATERIALS",
    "CATEGORY_MATERIAL",
    "CategoryMaterial",
    "MaterialSpec",
    "DEFORMABLE_SETTINGS",
    "category_material",
    "material",
    "deformable_settings",
]


@dataclass(frozen=True)
class MaterialSpec:
    """One row of the material table. SI units (kg/m^3, Pa); friction, restitution, Poisson's
    ratio and softness unitless; ``damping`` the unitless ratio used for soft bodies."""

    name: str
    density_kg_m3: float
    static_friction: float
    dynamic_friction: float
    restitution: float
    youngs_modulus_pa: float
    poisson_ratio: float
    softness: float
    source: str
    rgba: tuple[float, float, float, float] = (0.7, 0.7, 0.7, 1.0)
    damping: float = 0.0

    def to_material(self, rgba: tuple[float, float, float, float] | None = None) -> Material:
        """The model's :class:`Material` for this row (optionally with the observed colour)."""
        return Material(
            name=self.name,
            density_kg_m3=self.density_kg_m3,
            static_friction=self.static_friction,
            dynamic_friction=self.dynamic_friction,
            restitution=self.restitution,
            youngs_modulus_pa=self.youngs_modulus_pa,
            poisson_ratio=self.poisson_ratio,
            rgba=self.rgba if rgba is None else rgba,
            source=self.source,
        )


_ROWS = (
    # name, density, mu_s, mu_k, restitution, E, nu, softness, source, rgba, damping
    MaterialSpec("wood", 650.0, 0.45, 0.35, 0.50, 11.0e9, 0.35, 0.0,
                 "density: ETB wood species (pine 500 to oak 750, mean 650); E along grain, nu: USDA Wood Handbook tab. 5-1/5-2; friction wood on wood clean 0.25-0.5 (ETB)",
                 (0.55, 0.40, 0.26, 1.0)),
    MaterialSpec("particleboard", 700.0, 0.45, 0.35, 0.40, 3.0e9, 0.25, 0.0,
                 "density 600-800 (ETB densities of solids); E 2.5-4 GPa (MatWeb MDF); friction as wood (ETB)",
                 (0.75, 0.70, 0.62, 1.0)),
    MaterialSpec("steel", 7850.0, 0.55, 0.42, 0.60, 200.0e9, 0.29, 0.0,
                 "density, E, nu: CRC sec. 12 / ETB (structural steel); friction steel on steel dry 0.5-0.8 static, 0.42 kinetic (ETB)",
                 (0.75, 0.76, 0.78, 1.0)),
    MaterialSpec("aluminium", 2700.0, 0.61, 0.47, 0.55, 69.0e9, 0.33, 0.0,
                 "density, E, nu: CRC sec. 12; friction aluminium on mild steel 0.61 static, 0.47 kinetic (ETB)",
                 (0.80, 0.81, 0.83, 1.0)),
    MaterialSpec("plastic_abs", 1050.0, 0.40, 0.30, 0.60, 2.3e9, 0.35, 0.05,
                 "MatWeb typical ABS (1.04-1.06 g/cc, E 2.0-2.6 GPa, nu 0.35); friction polymer on steel 0.3-0.5 (ETB)",
                 (0.85, 0.85, 0.85, 1.0)),
    MaterialSpec("plastic_pp", 905.0, 0.30, 0.25, 0.60, 1.5e9, 0.42, 0.05,
                 "MatWeb typical polypropylene homopolymer (0.90-0.91 g/cc, E 1.1-1.9 GPa, nu 0.42); friction PP 0.25-0.35 (ETB)",
                 (0.30, 0.30, 0.32, 1.0)),
    MaterialSpec("plastic_pet", 1380.0, 0.40, 0.30, 0.60, 2.7e9, 0.37, 0.05,
                 "MatWeb typical PET (1.38 g/cc, E 2.7 GPa, nu 0.37); friction as polymer on steel (ETB)",
                 (0.75, 0.85, 0.90, 0.6)),
    MaterialSpec("glass", 2500.0, 0.50, 0.40, 0.70, 70.0e9, 0.22, 0.0,
                 "soda-lime glass: density 2.5 g/cc, E 70 GPa, nu 0.22 (CRC sec. 12, MatWeb); friction glass on metal 0.5-0.7 (ETB)",
                 (0.80, 0.90, 0.95, 0.5)),
    MaterialSpec("ceramic", 2400.0, 0.50, 0.40, 0.50, 70.0e9, 0.22, 0.0,
                 "porcelain / vitreous china: 2.3-2.5 g/cc, E 60-100 GPa, nu 0.22 (MatWeb porcelain); friction ceramic on ceramic 0.5 (ETB)",
                 (0.95, 0.95, 0.93, 1.0)),
    MaterialSpec("stone", 2700.0, 0.60, 0.50, 0.40, 50.0e9, 0.25, 0.0,
                 "granite: 2.69 g/cc, E 40-70 GPa, nu 0.25 (ETB densities / Young's modulus tables); friction stone 0.6 (ETB)",
                 (0.55, 0.55, 0.55, 1.0)),
    MaterialSpec("upholstery", 60.0, 0.60, 0.50, 0.10, 5.0e4, 0.30, 0.8,
                 "upholstered volume: flexible PU foam 30-50 kg/m^3 plus frame and fabric (MatWeb flexible polyurethane foam, E 20-100 kPa compressive, nu ~0.3); fabric friction 0.5-0.7 (ETB)",
                 (0.45, 0.45, 0.50, 1.0), 0.2),
    MaterialSpec("foam", 30.0, 0.60, 0.50, 0.05, 3.0e4, 0.30, 0.9,
                 "flexible polyurethane foam 20-50 kg/m^3, E 20-100 kPa, nu 0.3 (MatWeb)",
                 (0.90, 0.88, 0.82, 1.0), 0.2),
    MaterialSpec("fibre_fill", 25.0, 0.60, 0.50, 0.02, 1.0e4, 0.30, 1.0,
                 "polyester fibre pillow filling 15-30 kg/m^3 bulk (MatWeb polyester staple fibre, bulk); E ~10 kPa compressive estimate",
                 (0.92, 0.92, 0.90, 1.0), 0.3),
    MaterialSpec("fabric", 150.0, 0.70, 0.50, 0.05, 5.0e6, 0.30, 0.9,
                 "cotton terry 500 g/m^2 at 3.3 mm (150 kg/m^3 bulk); in-plane E of woven cotton 1-10 MPa; friction cotton 0.6-0.7 (ETB)",
                 (0.85, 0.80, 0.75, 1.0), 0.05),
    MaterialSpec("leather", 860.0, 0.50, 0.40, 0.20, 1.0e8, 0.40, 0.3,
                 "density 0.86 g/cc (ETB densities of solids); E 50-200 MPa; friction leather on wood 0.3-0.4, on metal 0.6 (ETB)",
                 (0.35, 0.22, 0.15, 1.0)),
    MaterialSpec("rubber", 1100.0, 1.00, 0.80, 0.80, 5.0e6, 0.49, 0.5,
                 "natural rubber 0.92-1.2 g/cc, E 1-10 MPa, nu 0.49 (ETB, MatWeb); friction rubber on dry surfaces 1.0 (ETB)",
                 (0.10, 0.10, 0.10, 1.0)),
    MaterialSpec("cardboard", 690.0, 0.50, 0.40, 0.20, 3.0e9, 0.30, 0.1,
                 "paperboard 0.69 g/cc (ETB densities of solids); E in-plane 3-5 GPa; friction paper on paper 0.4-0.5 (ETB)",
                 (0.70, 0.55, 0.38, 1.0)),
    MaterialSpec("paper", 800.0, 0.50, 0.40, 0.20, 3.0e9, 0.30, 0.1,
                 "bound paper (book) 0.7-0.9 g/cc (ETB densities of solids: paper 0.7-1.15); friction paper 0.4-0.5 (ETB)",
                 (0.85, 0.82, 0.75, 1.0)),
    # Composite effective materials: a closed envelope filled with parts and air. The density
    # is mass / envelope volume of typical products (spec sheets), not a bulk material.
    MaterialSpec("electronics", 350.0, 0.40, 0.30, 0.40, 2.3e9, 0.35, 0.0,
                 "effective: 55-inch TV 15 kg over 1.23x0.71x0.06 m (~290 kg/m^3), 24-inch monitor 4 kg in 0.55x0.35x0.05 m (~420); surfaces ABS (MatWeb)",
                 (0.12, 0.12, 0.13, 1.0)),
    MaterialSpec("laptop", 1100.0, 0.40, 0.30, 0.40, 69.0e9, 0.33, 0.0,
                 "effective: 1.5 kg laptop in 0.33x0.23x0.018 m (~1100 kg/m^3, spec sheets); aluminium shell friction (ETB)",
                 (0.60, 0.61, 0.63, 1.0)),
    MaterialSpec("potted_plant", 250.0, 0.60, 0.50, 0.30, 1.0e7, 0.30, 0.3,
                 "effective: 5 kg potted plant (pot, damp soil 1.2 g/cc, foliage) over a 0.3x0.3x0.5 m hull at ~45 % fill",
                 (0.25, 0.45, 0.20, 1.0)),
)

MATERIALS: dict[str, MaterialSpec] = {m.name: m for m in _ROWS}


@dataclass(frozen=True)
class CategoryMaterial:
    """Default construction of a category: material name and, for hollow objects, the panel
    (shell) thickness in metres (None = solid)."""

    material: str
    shell_thickness_m: float | None = None


# Panel thicknesses: 18 mm particleboard carcasses (EN 14322 standard furniture board), 0.6-1.5
# mm steel sheet for appliances, 4 mm corrugated board, 8 mm vitreous china for sanitary ware.
CATEGORY_MATERIAL: dict[str, CategoryMaterial] = {
    "table": CategoryMaterial("wood"),
    "desk": CategoryMaterial("particleboard"),
    "chair": CategoryMaterial("wood"),
    "stool": CategoryMaterial("wood"),
    "sofa": CategoryMaterial("upholstery"),
    "bed": CategoryMaterial("upholstery"),
    "shelf": CategoryMaterial("particleboard"),
    "cabinet": CategoryMaterial("particleboard", 0.018),
    "wardrobe": CategoryMaterial("particleboard", 0.018),
    "drawer_unit": CategoryMaterial("particleboard", 0.018),
    "refrigerator": CategoryMaterial("steel", 0.0012),
    "microwave": CategoryMaterial("steel", 0.0008),
    "oven": CategoryMaterial("steel", 0.0015),
    "dishwasher": CategoryMaterial("steel", 0.0010),
    "door": CategoryMaterial("wood"),
    "laptop": CategoryMaterial("laptop"),
    "box_with_lid": CategoryMaterial("cardboard", 0.004),
    "counter": CategoryMaterial("particleboard", 0.018),
    "sink": CategoryMaterial("ceramic", 0.008),
    "toilet": CategoryMaterial("ceramic", 0.008),
    "tv": CategoryMaterial("electronics"),
    "monitor": CategoryMaterial("electronics"),
    "lamp": CategoryMaterial("plastic_abs", 0.002),
    "plant": CategoryMaterial("potted_plant"),
    "box": CategoryMaterial("cardboard", 0.004),
    "bin": CategoryMaterial("plastic_pp", 0.002),
    "bottle": CategoryMaterial("plastic_pet", 0.0008),
    "mug": CategoryMaterial("ceramic"),
    "bowl": CategoryMaterial("ceramic"),
    "book": CategoryMaterial("paper"),
    "pillow": CategoryMaterial("fibre_fill"),
    "cushion": CategoryMaterial("foam"),
    "towel": CategoryMaterial("fabric"),
    "blanket": CategoryMaterial("fabric"),
    "soft_toy": CategoryMaterial("fibre_fill"),
    "bench": CategoryMaterial("wood"),
    "suitcase": CategoryMaterial("plastic_abs", 0.003),
    "bag": CategoryMaterial("fabric"),
    "vase": CategoryMaterial("ceramic", 0.006),
    "clock": CategoryMaterial("plastic_abs", 0.002),
    "keyboard": CategoryMaterial("plastic_abs", 0.002),
    "object": CategoryMaterial("plastic_abs", 0.003),
}

# Soft bodies: E and nu from the material rows; damping is the material's; thickness is the
# single-layer cloth thickness for shells (towel 3.3 mm terry, blanket 3 mm fleece); resolution
# is the number of simulation nodes per axis.
DEFORMABLE_SETTINGS: dict[str, DeformableSettings] = {
    "pillow": DeformableSettings(MATERIALS["fibre_fill"].youngs_modulus_pa, MATERIALS["fibre_fill"].poisson_ratio,
                                 MATERIALS["fibre_fill"].damping, 0.0, 5),
    "cushion": DeformableSettings(MATERIALS["foam"].youngs_modulus_pa, MATERIALS["foam"].poisson_ratio,
                                  MATERIALS["foam"].damping, 0.0, 5),
    "towel": DeformableSettings(MATERIALS["fabric"].youngs_modulus_pa, MATERIALS["fabric"].poisson_ratio,
                                MATERIALS["fabric"].damping, 0.0033, 8),
    "blanket": DeformableSettings(MATERIALS["fabric"].youngs_modulus_pa, MATERIALS["fabric"].poisson_ratio,
                                  MATERIALS["fabric"].damping, 0.003, 10),
    "soft_toy": DeformableSettings(MATERIALS["fibre_fill"].youngs_modulus_pa, MATERIALS["fibre_fill"].poisson_ratio,
                                   MATERIALS["fibre_fill"].damping, 0.0, 4),
}


def material(name: str, rgba: tuple[float, float, float, float] | None = None) -> Material:
    """The :class:`Material` named ``name`` (KeyError-free: raises ValueError naming the choices)."""
    spec = MATERIALS.get(name)
    if spec is None:
        raise ValueError(f"unknown material '{name}'; choose one of: {', '.join(sorted(MATERIALS))}")
    return spec.to_material(rgba)


def category_material(label: str) -> CategoryMaterial:
    """Default construction of ``label`` (unknown labels get the ``"object"`` default)."""
    return CATEGORY_MATERIAL.get(label, CATEGORY_MATERIAL["object"])


def deformable_settings(label: str) -> DeformableSettings | None:
    """Soft-body settings of a deformable category, None for rigid ones."""
    return DEFORMABLE_SETTINGS.get(label)
