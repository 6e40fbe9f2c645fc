"""How much teeth the soft evidence of `jawtrack segment` holds against the truth: per arch,
the teeth's true pixels (gt/masks/), and what the written labels and the shares
(`--debug DIR` with `"soft_evidence": true`: DIR/<camera>/<frame>-shares.png) count above
or below them, in all and per pixel the shares hold a part of. A share that reads a crown's
edge pixel as holding less than it does shows here as shares below the labels.

  jawtrack segment CAP -o T.json --segment-settings '{"soft_evidence": true}' --debug DIR
  shares_area.py CAP DIR

Needs numpy and pillow. Reads capture.json's mask values."""

import json
import os
import sys

import numpy as np
from PIL import Image


def main(cap, debug):
    masks = json.load(open(os.path.join(cap, "capture.json")))["masks"]
    totals = np.zeros((2, 4))
    for cam in sorted(os.listdir(debug)):
        for name in sorted(os.listdir(os.path.join(debug, cam))):
            if not name.endswith("-shares.png"):
                continue
            frame = name[: -len("-shares.png")] + ".png"
            shares = np.asarray(Image.open(os.path.join(debug, cam, name)), float) / 255
            truth = np.asarray(Image.open(os.path.join(cap, "gt", "masks", cam, frame)))
            labels = np.asarray(Image.open(os.path.join(cap, masks["dir"], cam, frame)))
            for a, value in enumerate([masks["upper"], masks["lower"]]):
                t, share = truth == value, shares[..., a]
                part = ((share > 0) & (share < 1)).sum()
                totals[a] += [t.sum(), (labels == value).sum() - t.sum(), share.sum() - t.sum(), part]
    for a, arch in enumerate(["upper", "lower"]):
        n, labels, shares, part = totals[a]
        print(f"{arch}: {n:.0f} true pixels; labels {labels:+.0f}, shares {shares:+.0f}; "
              f"{part:.0f} pixels held in part: labels {labels / part:+.3f}, shares {shares / part:+.3f} a pixel")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        sys.exit(__doc__)
    main(sys.argv[1], sys.argv[2])
