#!/usr/bin/env python3
"""Exports VGG-19 up to relu5_4 as ONNX with the outputs relu3_4, relu4_4, relu5_4 for
config/cnn_vgg19.yaml (the paper's layers). UNVERIFIED on the project's machines: the
ImageNet weights cannot be downloaded there. For users whose machines can:

    pip install torch torchvision onnx
    python scripts/export_vgg19.py -o models/vgg19/vgg19_conv3_4_5.onnx

Input `input` [1,3,H,W] (H, W dynamic), RGB, 0..255 minus the per-channel ImageNet mean
(123.68, 116.779, 103.939) as the preset sets it. torchvision's weights were trained on
(x/255 - mean)/std inputs; the first convolution is rescaled here so that the 0..255
mean-subtracted input the reference (MatConvNet) uses gives the same activations.
"""
import argparse

import torch
import torchvision

# Indices of the ReLUs after conv3_4, conv4_4, conv5_4 in torchvision's vgg19().features.
TAPS = {"relu3_4": 17, "relu4_4": 26, "relu5_4": 35}
STD = (0.229, 0.224, 0.225)


class Taps(torch.nn.Module):
    def __init__(self, features):
        super().__init__()
        self.features = features[: max(TAPS.values()) + 1]

    def forward(self, x):
        outs = {}
        for i, layer in enumerate(self.features):
            x = layer(x)
            for name, j in TAPS.items():
                if i == j:
                    outs[name] = x
        return tuple(outs[n] for n in TAPS)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("-o", "--output", required=True)
    args = ap.parse_args()
    vgg = torchvision.models.vgg19(weights=torchvision.models.VGG19_Weights.IMAGENET1K_V1)
    conv1 = vgg.features[0]
    with torch.no_grad():
        # (x - mean)/255/std: fold 1/(255 std) into conv1's input channels.
        for c, s in enumerate(STD):
            conv1.weight[:, c] /= 255.0 * s
    model = Taps(vgg.features).eval()
    x = torch.zeros(1, 3, 224, 224)
    torch.onnx.export(model, x, args.output, input_names=["input"], output_names=list(TAPS),
                      dynamic_axes={"input": {2: "H", 3: "W"}}, opset_version=13)
    print("wrote", args.output)


if __name__ == "__main__":
    main()
