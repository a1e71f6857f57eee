"""The step maps of the built-in scene pendula_map.toml, written as a user writes a scene's maps:
plain numpy on (n, k) arrays, step(x, v, h) -> (x, v), positions wrapped into [0, 2π).

A ring of K coupled pendula, H = Σ v²/2 + Σ (1 − cos x_i) + c Σ (1 − cos(x_{i+1} − x_i)), c = 1/2,
advanced by Strang splitting (kick ½h, drift h, kick ½h: symplectic) and by the explicit midpoint
rule RK2 (not).  The same system and arithmetic as ``integrators.audit.examples.pendulum_array``
(tests/test_user_scenes.py checks that the two give the same bits)."""
import numpy as np

K = 256                                   # the scene's system.degrees_of_freedom
COUPLING = 0.5
TWO_PI = 2 * np.pi


def force(x):
    """−∂H/∂x on rows of angles (n, K)."""
    right = np.roll(x, -1, axis=1) - x
    left = x - np.roll(x, 1, axis=1)
    return -np.sin(x) + COUPLING * (np.sin(right) - np.sin(left))


def _wrap(x):
    return x - TWO_PI * np.floor(np.real(x) / TWO_PI)


def strang(x, v, h):
    v = v + 0.5 * h * force(x)
    x = x + h * v
    v = v + 0.5 * h * force(x)
    return _wrap(x), v


def rk2(x, v, h):
    xm = x + 0.5 * h * v
    vm = v + 0.5 * h * force(x)
    return _wrap(x + h * vm), v + h * force(xm)


def energy(x, v):
    right = np.roll(x, -1, axis=-1) - x
    return np.sum(0.5 * v * v + (1 - np.cos(x)) + COUPLING * (1 - np.cos(right)), axis=-1)


def start():
    """The loop's centre (x0, v0): angles uniform in [0, 2π), momenta normal with deviation 0.5
    (numpy's generator of seed 1)."""
    rng = np.random.default_rng(1)
    return rng.uniform(0.0, TWO_PI, K), 0.5 * rng.standard_normal(K)
