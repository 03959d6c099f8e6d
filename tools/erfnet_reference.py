#!/usr/bin/python3
"""ErfNet (Romera et al. 2018) in PyTorch, exactly as issue #9 states it and with the reference module
naming (encoder.initial_block.conv.weight, encoder.layers.N.conv3x1_1.weight, decoder.output_conv.weight,
...), so that state_dicts of the reference code load into it and tools/erfnet_export.py can read it.

Run it directly to print the parameter count and the MACs at 640x400 (the issue says 2.07 M, ~13 GMAC).
"""
import sys

import torch
import torch.nn as nn
import torch.nn.functional as F

BN_EPS = 1e-3
# The encoder's 128-channel blocks and their dilations (the 64-channel ones all use dilation 1).
ENCODER_DILATIONS = [2, 4, 8, 16, 2, 4, 8, 16]


class DownsamplerBlock(nn.Module):
    """3x3 stride-2 conv to (out - in) channels, concatenated (conv first) with a 2x2 max-pool; BN, ReLU."""

    def __init__(self, ninput, noutput):
        super().__init__()
        self.conv = nn.Conv2d(ninput, noutput - ninput, (3, 3), stride=2, padding=1, bias=True)
        self.pool = nn.MaxPool2d(2, stride=2)
        self.bn = nn.BatchNorm2d(noutput, eps=BN_EPS)

    def forward(self, x):
        return F.relu(self.bn(torch.cat([self.conv(x), self.pool(x)], 1)))


class non_bottleneck_1d(nn.Module):  # noqa: N801 (the reference name)
    def __init__(self, chann, dropprob, dilated):
        super().__init__()
        self.conv3x1_1 = nn.Conv2d(chann, chann, (3, 1), stride=1, padding=(1, 0), bias=True)
        self.conv1x3_1 = nn.Conv2d(chann, chann, (1, 3), stride=1, padding=(0, 1), bias=True)
        self.bn1 = nn.BatchNorm2d(chann, eps=BN_EPS)
        self.conv3x1_2 = nn.Conv2d(chann, chann, (3, 1), stride=1, padding=(dilated, 0), bias=True,
                                   dilation=(dilated, 1))
        self.conv1x3_2 = nn.Conv2d(chann, chann, (1, 3), stride=1, padding=(0, dilated), bias=True,
                                   dilation=(1, dilated))
        self.bn2 = nn.BatchNorm2d(chann, eps=BN_EPS)
        self.dropout = nn.Dropout2d(dropprob)

    def forward(self, x):
        y = F.relu(self.conv3x1_1(x))
        y = F.relu(self.bn1(self.conv1x3_1(y)))
        y = F.relu(self.conv3x1_2(y))
        y = self.bn2(self.conv1x3_2(y))
        if self.dropout.p != 0:
            y = self.dropout(y)
        return F.relu(y + x)


class Encoder(nn.Module):
    def __init__(self, num_classes):
        super().__init__()
        self.initial_block = DownsamplerBlock(3, 16)
        self.layers = nn.ModuleList()
        self.layers.append(DownsamplerBlock(16, 64))
        for _ in range(5):
            self.layers.append(non_bottleneck_1d(64, 0.03, 1))
        self.layers.append(DownsamplerBlock(64, 128))
        for d in ENCODER_DILATIONS:
            self.layers.append(non_bottleneck_1d(128, 0.3, d))
        # Only used when the encoder is trained alone (the reference's predict=True); not part of Net's output.
        self.output_conv = nn.Conv2d(128, num_classes, 1, stride=1, padding=0, bias=True)

    def forward(self, x, predict=False):
        y = self.initial_block(x)
        for layer in self.layers:
            y = layer(y)
        return self.output_conv(y) if predict else y


class UpsamplerBlock(nn.Module):
    def __init__(self, ninput, noutput):
        super().__init__()
        self.conv = nn.ConvTranspose2d(ninput, noutput, 3, stride=2, padding=1, output_padding=1, bias=True)
        self.bn = nn.BatchNorm2d(noutput, eps=BN_EPS)

    def forward(self, x):
        return F.relu(self.bn(self.conv(x)))


class Decoder(nn.Module):
    def __init__(self, num_classes):
        super().__init__()
        self.layers = nn.ModuleList()
        self.layers.append(UpsamplerBlock(128, 64))
        self.layers.append(non_bottleneck_1d(64, 0, 1))
        self.layers.append(non_bottleneck_1d(64, 0, 1))
        self.layers.append(UpsamplerBlock(64, 16))
        self.layers.append(non_bottleneck_1d(16, 0, 1))
        self.layers.append(non_bottleneck_1d(16, 0, 1))
        self.output_conv = nn.ConvTranspose2d(16, num_classes, 2, stride=2, padding=0, output_padding=0, bias=True)

    def forward(self, x):
        y = x
        for layer in self.layers:
            y = layer(y)
        return self.output_conv(y)


class Net(nn.Module):
    def __init__(self, num_classes):
        super().__init__()
        self.encoder = Encoder(num_classes)
        self.decoder = Decoder(num_classes)

    def forward(self, x):
        return self.decoder(self.encoder(x))


def count_macs(net, height, width):
    """Multiply-accumulates of one forward pass (convolutions only), by hooks on a dummy run."""
    macs = [0]

    def hook(m, inp, out):
        if isinstance(m, nn.Conv2d):
            macs[0] += out.numel() * (m.in_channels // m.groups) * m.kernel_size[0] * m.kernel_size[1]
        elif isinstance(m, nn.ConvTranspose2d):
            macs[0] += inp[0].numel() * m.out_channels * m.kernel_size[0] * m.kernel_size[1]

    hooks = [m.register_forward_hook(hook) for m in net.modules() if isinstance(m, (nn.Conv2d, nn.ConvTranspose2d))]
    with torch.no_grad():
        net(torch.zeros(1, 3, height, width))
    for h in hooks:
        h.remove()
    # The encoder's own output_conv does not run inside Net.
    return macs[0]


def main():
    classes = int(sys.argv[1]) if len(sys.argv) > 1 else 20
    net = Net(classes).eval()
    params = sum(p.numel() for n, p in net.named_parameters() if not n.startswith("encoder.output_conv"))
    print(f"ErfNet, {classes} classes: {params / 1e6:.3f} M parameters (without encoder.output_conv), "
          f"{count_macs(net, 400, 640) / 1e9:.2f} GMAC at 640x400")


if __name__ == "__main__":
    main()
