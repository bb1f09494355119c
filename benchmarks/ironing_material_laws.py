"""How much the ironing forces depend on the form of the compressible Neo-Hookean law.

The ironing reference (benchmarks.md, section 3) names "Neo-Hookean" with E and nu
but not the volumetric part, and compressible Neo-Hookean laws differ there. This
runs ``demos/ironing.py`` with four common forms (mu, lambda from E, nu; plane
strain, I1 = tr C + 1):

* ``ln J squared`` (the library's): mu/2 (I1 - 3 - 2 ln J) + lambda/2 (ln J)^2
* ``Ciarlet``: mu/2 (I1 - 3 - 2 ln J) + lambda/4 (J^2 - 1) - lambda/2 ln J
* ``decoupled``: mu/2 (J^(-2/3) I1 - 3) + kappa/2 (J - 1)^2, kappa = lambda + 2 mu / 3
* ``Holzapfel``: mu/2 (I1 - 3) + mu/(2 beta) (J^(-2 beta) - 1), beta = nu / (1 - 2 nu)

and prints the vertical force at t = 1 and its mean over the plateau window
against the reference values.

    tools/run python3 benchmarks/ironing_material_laws.py --steps 200 --end-time 1.5 \\
        --markdown benchmarks/results/ironing_material_laws.md
"""

from __future__ import annotations

import argparse
import pathlib
import sys

import ufl

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parents[1] / "demos"))

import ironing  # noqa: E402

from dolfinx_mortar import materials  # noqa: E402


def energy(law: str, F, mu: float, lmbda: float):
    J = ufl.det(F)
    I1 = ufl.tr(F.T * F) + 1.0
    if law == "ln J squared":
        return 0.5 * mu * (I1 - 3 - 2 * ufl.ln(J)) + 0.5 * lmbda * ufl.ln(J) ** 2
    if law == "Ciarlet":
        return (
            0.5 * mu * (I1 - 3 - 2 * ufl.ln(J))
            + 0.25 * lmbda * (J**2 - 1)
            - 0.5 * lmbda * ufl.ln(J)
        )
    if law == "decoupled":
        kappa = lmbda + 2.0 * mu / 3.0
        return 0.5 * mu * (J ** (-2.0 / 3.0) * I1 - 3) + 0.5 * kappa * (J - 1) ** 2
    if law == "Holzapfel":
        nu = lmbda / (2.0 * (lmbda + mu))
        beta = nu / (1.0 - 2.0 * nu)
        return 0.5 * mu * (I1 - 3) + 0.5 * mu / beta * (J ** (-2.0 * beta) - 1)
    raise ValueError(law)


LAWS = ("ln J squared", "Ciarlet", "decoupled", "Holzapfel")


def main(argv=None) -> list[dict]:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--end-time", type=float, default=1.5)
    parser.add_argument("--markdown", type=pathlib.Path)
    args = parser.parse_args(argv)
    original = materials.STRESS["neo-hookean"]
    rows = []
    try:
        for law in LAWS:

            def stress(u, mu, lmbda, law=law):
                F = ufl.variable(materials.deformation_gradient(u))
                return ufl.diff(energy(law, F, mu, lmbda), F)

            materials.STRESS["neo-hookean"] = stress
            summary = ironing.main(["--steps", str(args.steps), "--end-time", str(args.end_time)])
            rows.append(
                {
                    "law": law,
                    **{
                        key: summary.get(key)
                        for key in (
                            "vertical_force_at_t1",
                            "vertical_force_plateau_mean",
                            "plateau_error_rel",
                            "steps_completed",
                            "newton_iterations",
                        )
                    },
                }
            )
    finally:
        materials.STRESS["neo-hookean"] = original
    reference = ironing.REFERENCE
    lines = [
        f"Ironing, {args.steps} steps over t in [0, 2], run to t = {args.end_time}; "
        "vertical force at t = 1 and mean over the plateau window (reference "
        f"{reference['vertical_force_at_t1']:.3g} and "
        f"{reference['vertical_force_plateau_mean']:.3g}).",
        "",
        "| Neo-Hookean form | V(t = 1) | against reference | plateau mean | against reference "
        "| max Newton |",
        "|---|---|---|---|---|---|",
    ]
    for r in rows:
        v1, plateau = r["vertical_force_at_t1"], r["vertical_force_plateau_mean"]
        v1_error = v1 / reference["vertical_force_at_t1"] - 1.0
        lines.append(
            f"| {r['law']} | {v1:.4g} | {100 * v1_error:+.1f} % "
            f"| {plateau:.4g} | {100 * r['plateau_error_rel']:+.1f} % "
            f"| {max(r['newton_iterations'])} |"
        )
    text = "\n".join(lines) + "\n"
    print(text)
    if args.markdown:
        args.markdown.write_text(text)
    return rows


if __name__ == "__main__":
    main()
