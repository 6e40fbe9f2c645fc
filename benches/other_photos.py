"""Colour pictures for benches/other_capture.py: what a camera films of the scene that program
draws, by its own shading model (no code or constant shared with jawtrack's `synth`).

  - drawn at twice the pictures' size and averaged down, so a pixel on an edge mixes both sides
    in proportion to what covers it (as a sensor's pixel does), then a lens blur and noise;
  - enamel lit by a light beside the camera (Lambert and Blinn-Phong), each subject's tooth
    shade, skin tone and lip colour drawn from a range (pale to dark skin);
  - lips as a band around the opening, skin beyond, the mouth interior dark red;
  - `hard`: gums where the opening shows them beyond the crowns, the tongue in the opening's
    lower part, wet highlights on enamel and tongue, crowns shaded near the lips, motion blur
    (the mean over three poses across the shutter), white balance and exposure drifting.

The true labels are those other_capture.py writes (pixel centres at the middle pose); gums and
tongue are the mouth interior, as the capture format has it.
"""
import numpy as np


def face_normals(v, f):
    n = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)


def subject(rng):
    """One person's colours (linear RGB): tooth shade, skin, lips."""
    tone = rng.uniform(0.0, 1.0)  # 0 pale, 1 dark
    skin = np.array([0.78, 0.52, 0.40]) * (1.0 - 0.7 * tone)
    lip = np.array([0.55, 0.20, 0.22]) * (1.0 - 0.55 * tone)
    enamel = np.array([0.86, 0.80, 0.64]) * rng.uniform(0.9, 1.05, 3).clip(0, 1 / 0.86)
    return {"skin": skin, "lip": lip, "enamel": enamel,
            "interior": np.array([0.09, 0.02, 0.025]), "gum": np.array([0.70, 0.28, 0.30]),
            "tongue": np.array([0.62, 0.27, 0.27])}


def band(mask, px):
    """Pixels within px (4-neighbour steps) of mask, mask excluded."""
    m = mask.copy()
    for _ in range(px):
        g = m.copy()
        g[1:] |= m[:-1]
        g[:-1] |= m[1:]
        g[:, 1:] |= m[:, :-1]
        g[:, :-1] |= m[:, 1:]
        m = g
    return m & ~mask


def reach_along(mask, px, down):
    """Pixels that have a pixel of mask within px below them (down) or above."""
    out = np.zeros_like(mask)
    for k in range(1, px + 1):
        if down:
            out[:-k] |= mask[k:]
        else:
            out[k:] |= mask[:-k]
    return out


def shade(look, fid, normals, opening, colours, cam_axis, hard, rng):
    """One pose's picture at the drawn size (linear RGB, h x w x 3). look: the label per pixel
    (1 upper, 2 lower, 0 none) before the lips; fid: the face drawn (index into normals, -1)."""
    h, w = look.shape
    teeth = (look > 0) & opening
    yy, xx = np.mgrid[0:h, 0:w]
    # Skin with a soft gradient and a mottled texture; lips a band around the opening.
    mottled = 1.0 + 0.04 * np.sin(xx / 37.0 + 1.3) * np.sin(yy / 23.0)
    out = colours["skin"][None, None] * (0.85 + 0.15 * yy / h)[..., None] * mottled[..., None]
    lips = band(opening, max(6, w // 50))
    out[lips] = colours["lip"] * (0.9 + 0.1 * np.sin(xx[lips] / 9.0))[:, None]
    inner = opening & ~teeth
    out[inner] = colours["interior"]
    if hard:
        gums = inner & (reach_along(look == 1, w // 160, True) | reach_along(look == 2, w // 160, False))
        rows = np.where(opening.any(axis=1))[0]
        if len(rows):
            top, bottom = rows.min(), rows.max()
            tongue = inner & (yy > bottom - 0.3 * (bottom - top))
            out[tongue] = colours["tongue"] * (0.7 + 0.3 * (yy[tongue] - top) / max(bottom - top, 1))[:, None]
        out[gums] = colours["gum"]
    # Enamel: a light beside the camera, Lambert and (hard) wet highlights.
    light = cam_axis + np.array([0.0, 0.35, 0.0])
    light /= np.linalg.norm(light)
    half = light + cam_axis
    half /= np.linalg.norm(half)
    n = normals[fid[teeth]]
    diffuse = np.abs(n @ light)
    c = colours["enamel"][None] * (0.3 + 0.7 * diffuse)[:, None]
    if hard:
        c += 0.9 * (np.abs(n @ half) ** 120)[:, None]
        shadow = band(~opening, w // 120)[teeth]
        c[shadow] *= 0.55
    out[teeth] = c
    return out


def photo(renders, colours, frame, frames, hard, rng):
    """The picture (uint8 h/2 x w/2 x 3) from the shutter's renders (each shade()'s output at
    twice the size): averaged over the shutter and down to size, exposure and white balance,
    lens blur, noise, sRGB."""
    img = np.mean(renders, axis=0)
    h, w, _ = img.shape
    img = img.reshape(h // 2, 2, w // 2, 2, 3).mean(axis=(1, 3))
    s = frame / max(frames - 1, 1)
    if hard:
        img = img * (1.0 + 0.12 * np.sin(2 * np.pi * s)) * \
            np.array([1.0 + 0.06 * np.sin(2 * np.pi * s + 1), 1.0, 1.0 - 0.06 * np.sin(2 * np.pi * s + 1)])
    k = np.exp(-0.5 * (np.arange(-2, 3) / (0.9 if hard else 0.6)) ** 2)
    k /= k.sum()
    for axis in (0, 1):
        img = sum(wt * np.roll(img, d, axis=axis) for d, wt in zip(range(-2, 3), k))
    img = img + rng.normal(0.0, 0.012 if hard else 0.006, img.shape)
    srgb = np.where(img <= 0.0031308, 12.92 * img, 1.055 * np.clip(img, 0, None) ** (1 / 2.4) - 0.055)
    return (np.clip(srgb, 0, 1) * 255 + 0.5).astype(np.uint8)
