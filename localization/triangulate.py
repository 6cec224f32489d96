"""Where rays from several places cross: the least-squares point nearest them and its standard
error (:func:`localization.locate`'s uncertainty, from each capture's own best direction)."""

from __future__ import annotations

import numpy as np


def triangulate(centers: np.ndarray, directions: np.ndarray, *, axes: bool = False) -> tuple[np.ndarray, float]:
    """Least-squares point nearest rays ``centers + t * directions``, and its standard error.

    Parameters
    ----------
    centers : numpy.ndarray [shape=(n, 3)]
        The rays' origins in metres.
    directions : numpy.ndarray [shape=(n, 3)]
        The rays' unit directions.
    axes : bool
        Give the standard error on each of x, y and z (default False: its norm).

    Returns
    -------
    x : numpy.ndarray [shape=(3,)]
        The point in metres.
    sigma : float or numpy.ndarray [shape=(3,)]
        Its standard error in metres (on each axis where ``axes``); ``inf`` (unknown) for fewer
        than three rays, or for rays all parallel (no crossing: ``x`` is then their common line's
        point nearest the origin).

    Examples
    --------
    >>> import numpy as np
    >>> from localization.triangulate import triangulate
    >>> centers = np.array([[0.0, 0, 0], [2.0, 0, 0]])
    >>> directions = np.array([[1.0, 1, 0], [-1.0, 1, 0]]) / np.sqrt(2)
    >>> x, sigma = triangulate(centers, directions)
    >>> x.round(3)
    array([1., 1., 0.])
    """
    P = np.eye(3)[None] - directions[:, :, None] * directions[:, None, :]
    A = P.sum(axis=0)
    x = np.linalg.lstsq(A, np.einsum("nij,nj->i", P, centers), rcond=1e-8)[0]
    if len(centers) < 3 or np.linalg.cond(A) > 1e8:
        return x, np.full(3, np.inf) if axes else float("inf")
    resid = np.einsum("nij,nj->ni", P, x - centers)
    sigma2 = (resid ** 2).sum() / (2 * len(centers) - 3)
    var = np.diag(np.linalg.inv(A)) * sigma2
    return x, np.sqrt(np.maximum(var, 0)) if axes else float(np.sqrt(np.maximum(var, 0).sum()))
