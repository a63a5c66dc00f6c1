"""Export the feature taps of a torchvision backbone to ONNX for ``cost.kind: features``.

Run once on a machine with internet access and PyTorch; d3stereo itself never needs
torch, and never downloads weights at run time: it reads the ONNX file this writes.

    pip install torch torchvision onnx
    python scripts/export_backbone.py vgg16 -o vgg16.onnx
    d3stereo run PAIRS -o OUT --set cost.kind=features --set features.model=vgg16.onnx \\
        --set "features.outputs=[s1, s2, s4, s8]"

The outputs are named ``s<stride>`` (stride relative to the input image), finest first;
list the ones to use in ``features.outputs``.  The taps (the paper's Table IV backbones):

=================  =====================================================  ==============
backbone           taps (torchvision module names)                         strides
=================  =====================================================  ==============
vgg16              features.3, .8, .15, .22 (relu1_2, 2_2, 3_3, 4_3)        1, 2, 4, 8
resnet18/resnet50  relu, layer1, layer2, layer3                            2, 4, 8, 16
mobilenet_v3       features.0, .1, .3, .6 (large)                          2, 2, 4, 8
=================  =====================================================  ==============

(The MobileNetV3 stem and first block share stride 2: keep one of them in
``features.outputs``, e.g. ``[s2, s4, s8]``; this script names duplicates ``s2``,
``s2b``.)  Preprocessing is ImageNet's: RGB, x / 255, mean (0.485, 0.456, 0.406), std
(0.229, 0.224, 0.225) -- the defaults of the ``features`` config section.
"""

from __future__ import annotations

import argparse
import sys

TAPS = {
    "vgg16": ("vgg16", ["features.3", "features.8", "features.15", "features.22"]),
    "resnet18": ("resnet18", ["relu", "layer1", "layer2", "layer3"]),
    "resnet50": ("resnet50", ["relu", "layer1", "layer2", "layer3"]),
    "mobilenet_v3": ("mobilenet_v3_large", ["features.0", "features.1", "features.3", "features.6"]),
}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("backbone", choices=sorted(TAPS))
    parser.add_argument("-o", "--out", required=True, help="ONNX file to write")
    parser.add_argument("--size", default="256x512", help="HxW of the example input (axes stay dynamic)")
    args = parser.parse_args(argv)
    try:
        import torch
        import torchvision
        from torchvision.models.feature_extraction import create_feature_extractor
    except ImportError:
        print("Error: this script needs PyTorch and torchvision (pip install torch torchvision onnx); "
              "d3stereo itself does not depend on them", file=sys.stderr)
        return 1
    name, taps = TAPS[args.backbone]
    model = getattr(torchvision.models, name)(weights="DEFAULT").eval()
    extractor = create_feature_extractor(model, return_nodes=taps)
    height, width = (int(x) for x in args.size.split("x"))
    example = torch.zeros(1, 3, height, width)
    with torch.no_grad():
        maps = extractor(example)
    names, seen = [], set()
    for tap in taps:
        stride = height // maps[tap].shape[2]
        label = f"s{stride}"
        while label in seen:
            label += "b"
        seen.add(label)
        names.append(label)

    class Taps(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.extractor = extractor

        def forward(self, image):
            out = self.extractor(image)
            return tuple(out[tap] for tap in taps)

    dynamic = {"image": {2: "height", 3: "width"}, **{n: {2: f"h_{n}", 3: f"w_{n}"} for n in names}}
    torch.onnx.export(Taps(), example, args.out, input_names=["image"], output_names=names,
                      dynamic_axes=dynamic, opset_version=17)
    print(f"wrote {args.out}: outputs {', '.join(names)} (finest first)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
