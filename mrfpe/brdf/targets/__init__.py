"""The BRDF pseudolikelihood family on a scene's corner-vertex lattice.

PL (4.23-4.24, 5.64-5.66), PL2 (6.54-6.59), PL3 (6.60-6.62), PL_s (7.5-7.7) and,
beyond the thesis, the image fit and a composite marginal likelihood
(:mod:`~mrfpe.brdf.targets.pseudolikelihood`), built on their base class
(:mod:`~mrfpe.brdf.targets.brdf_target`), data energies
(:mod:`~mrfpe.brdf.targets.energy`), tables (:mod:`~mrfpe.brdf.targets.tables`),
the radiance coefficients of every BRDF (:mod:`~mrfpe.brdf.targets.reflectance`),
least-squares residuals (:mod:`~mrfpe.brdf.targets.residuals`) and their analytic
Jacobians (:mod:`~mrfpe.brdf.targets.jacobian`). Users build them by name through
the core's door, ``mrfpe.targets.get("pl", scene, ...)``; they register under the
``mrfpe.targets`` entry-point group.
"""
