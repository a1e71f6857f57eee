"""The step maps of the built-in scene pendula_map.toml: a ring of coupled pendula advanced by a
Strang splitting (symplectic) and by the explicit midpoint rule RK2 (not), from
integrators.audit.examples.  Canonical maps step(x, v, h) -> (x, v) on (n, k) arrays."""
import numpy as np

from integrators.audit.examples import pendulum_array

K = 256                                   # the scene's system.degrees_of_freedom

strang = pendulum_array(K, method="strang")[0]
rk2 = pendulum_array(K, method="rk2")[0]
energy = pendulum_array(K)[1]["energy"]


def start():
    """The loop's centre (x0, v0): angles uniform in [0, 2π), momenta normal with deviation 0.5
    (numpy's generator of seed 1), as integrators.audit.examples.example('pendula-strang')."""
    rng = np.random.default_rng(1)
    return rng.uniform(0.0, 2 * np.pi, K), 0.5 * rng.standard_normal(K)
