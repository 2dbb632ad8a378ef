"""PointNet's classification network (Qi et al., CVPR 2017) and its training loss.

Plain module-level :class:`torch.nn.Module` classes, so that pickling a
trained network (or a skorch net holding one) needs nothing special.
"""

import torch
from torch import nn

from ._networks import MAX_PARAMETERS, check_network_values

__all__ = ["PointNet", "PointNetLoss", "TNet", "orthogonality_penalty"]


class TNet(nn.Module):
    """Predicts a ``k x k`` transform from a (batch, k, n_points) input.

    Shared MLP (64, 128, 1024), max-pool, dense 512-256-k*k with batch norm.
    The last layer starts with zero weights and the identity as bias, so the
    predicted transform is exactly the identity at initialization.

    Parameters
    ----------
    k : int
        Dimension of the transformed features (3 for the input transform,
        64 for the feature transform).

    See Also
    --------
    PointNet : The network that uses two of them.
    orthogonality_penalty : The regularizer of the predicted transforms.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import TNet
    >>> TNet(3).eval()(torch.zeros(2, 3, 10)).shape
    torch.Size([2, 3, 3])
    """

    def __init__(self, k):
        super().__init__()
        self.k = k
        self.features = nn.Sequential(
            nn.Conv1d(k, 64, 1), nn.BatchNorm1d(64), nn.ReLU(),
            nn.Conv1d(64, 128, 1), nn.BatchNorm1d(128), nn.ReLU(),
            nn.Conv1d(128, 1024, 1), nn.BatchNorm1d(1024), nn.ReLU(),
        )
        self.head = nn.Sequential(
            nn.Linear(1024, 512), nn.BatchNorm1d(512), nn.ReLU(),
            nn.Linear(512, 256), nn.BatchNorm1d(256), nn.ReLU(),
        )
        self.out = nn.Linear(256, k * k)
        nn.init.zeros_(self.out.weight)
        with torch.no_grad():
            self.out.bias.copy_(torch.eye(k).flatten())

    def forward(self, x):
        """Predict one transform per sample.

        Parameters
        ----------
        x : torch.Tensor of shape (batch, k, n_points)
            Per-point features.

        Returns
        -------
        transform : torch.Tensor of shape (batch, k, k)
            The predicted transforms.
        """
        g = self.features(x).max(dim=2).values
        return self.out(self.head(g)).view(-1, self.k, self.k)


class PointNet(nn.Module):
    """PointNet classification network on (batch, n_points, 3) input.

    A learned 3 x 3 input transform, a shared MLP (64, 64), a learned
    64 x 64 feature transform, a shared MLP (64, 128, 1024), a global
    max-pool and a dense head 512-256-classes with batch norm and dropout.

    Parameters
    ----------
    n_classes : int
        Number of classes, at least 2; the network (3.5 million parameters
        besides the last layer's ``257 * n_classes``) may have at most a
        billion parameters.
    dropout : float, default=0.3
        Dropout probability before the last dense layer, in [0, 1).

    See Also
    --------
    PointNetLoss : Its training loss.
    TNet : The transform networks.
    eppf.classifiers.PointNetClassifier : The scikit-learn classifier that trains it.

    Notes
    -----
    The forward pass returns ``(logits, feature_transform)``: the logits of
    shape (batch, n_classes) and the 64 x 64 feature transform of shape
    (batch, 64, 64) that the orthogonality regularizer needs (see
    :class:`PointNetLoss`).

    References
    ----------
    .. [1] C. R. Qi, H. Su, K. Mo and L. J. Guibas, "PointNet: Deep Learning
       on Point Sets for 3D Classification and Segmentation", CVPR 2017.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import PointNet
    >>> logits, feat = PointNet(n_classes=4).eval()(torch.zeros(2, 16, 3))
    >>> tuple(logits.shape), tuple(feat.shape)
    ((2, 4), (2, 64, 64))
    """

    def __init__(self, n_classes, dropout=0.3):
        super().__init__()
        # (checked before any layer: a float n_classes failed in torch.empty, a huge one in torch's
        # allocator with a RuntimeError, and 0 classes or a dropout of 2 built a network that could not train)
        check_network_values("PointNet", n_classes=n_classes, dropout=dropout)
        n_classes, dropout = int(n_classes), float(dropout)
        if 257 * n_classes > MAX_PARAMETERS:
            raise ValueError(f"PointNet: n_classes={n_classes:,} gives the last layer {257 * n_classes:,} parameters, "
                             f"more than the {MAX_PARAMETERS:,} a network may have; use fewer classes")
        self.input_tnet = TNet(3)
        self.mlp1 = nn.Sequential(
            nn.Conv1d(3, 64, 1), nn.BatchNorm1d(64), nn.ReLU(),
            nn.Conv1d(64, 64, 1), nn.BatchNorm1d(64), nn.ReLU(),
        )
        self.feature_tnet = TNet(64)
        self.mlp2 = nn.Sequential(
            nn.Conv1d(64, 64, 1), nn.BatchNorm1d(64), nn.ReLU(),
            nn.Conv1d(64, 128, 1), nn.BatchNorm1d(128), nn.ReLU(),
            nn.Conv1d(128, 1024, 1), nn.BatchNorm1d(1024), nn.ReLU(),
        )
        self.head = nn.Sequential(
            nn.Linear(1024, 512), nn.BatchNorm1d(512), nn.ReLU(),
            nn.Linear(512, 256), nn.BatchNorm1d(256), nn.ReLU(),
            nn.Dropout(p=dropout),
            nn.Linear(256, n_classes),
        )

    def forward(self, X):
        """Compute the logits and the feature transform of a batch of clouds.

        Parameters
        ----------
        X : torch.Tensor of shape (batch, n_points, 3)
            Point coordinates.

        Returns
        -------
        logits : torch.Tensor of shape (batch, n_classes)
            Class scores.
        feature_transform : torch.Tensor of shape (batch, 64, 64)
            The learned feature transform, for the regularizer.
        """
        x = X.transpose(1, 2)  # (batch, 3, n_points)
        x = torch.bmm(self.input_tnet(x), x)
        x = self.mlp1(x)
        feat = self.feature_tnet(x)
        x = torch.bmm(feat, x)
        g = self.mlp2(x).max(dim=2).values
        return self.head(g), feat


def orthogonality_penalty(A):
    """Batch mean of the squared Frobenius norm of ``I - A A^T``.

    Parameters
    ----------
    A : torch.Tensor of shape (batch, k, k)
        Transforms.

    Returns
    -------
    penalty : torch.Tensor, a scalar
        Zero when every transform is orthogonal.

    See Also
    --------
    PointNetLoss : The loss that adds it to the cross-entropy.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import orthogonality_penalty
    >>> float(orthogonality_penalty(torch.eye(3).expand(2, 3, 3)))
    0.0
    """
    eye = torch.eye(A.shape[-1], dtype=A.dtype, device=A.device)
    diff = eye - torch.bmm(A, A.transpose(1, 2))
    return (diff**2).sum(dim=(1, 2)).mean()


class PointNetLoss(nn.Module):
    """Cross-entropy plus ``reg_weight * mean ||I - A A^T||_F^2``.

    Takes the network's ``(logits, feature_transform)`` pair as prediction,
    so skorch adds the regularizer to every training and validation loss
    without a custom ``get_loss``.

    Parameters
    ----------
    reg_weight : float, default=0.001
        Weight of the feature-transform regularizer.

    See Also
    --------
    PointNet : The network whose output it takes.
    orthogonality_penalty : The regularizer.

    Examples
    --------
    >>> import torch
    >>> from eppf.nn import PointNetLoss
    >>> logits, y = torch.zeros(2, 3), torch.tensor([0, 2])
    >>> loss = PointNetLoss()((logits, torch.eye(64).expand(2, 64, 64)), y)
    >>> round(float(loss), 4)  # log(3): the penalty is 0 for orthogonal transforms
    1.0986
    """

    def __init__(self, reg_weight=0.001):
        super().__init__()
        self.reg_weight = reg_weight
        self.ce = nn.CrossEntropyLoss()

    def forward(self, y_pred, y_true):
        """Compute the regularized loss of a batch.

        Parameters
        ----------
        y_pred : tuple of torch.Tensor
            The network's ``(logits, feature_transform)``.
        y_true : torch.Tensor of shape (batch,)
            Class indices.

        Returns
        -------
        loss : torch.Tensor, a scalar
            Cross-entropy plus the weighted orthogonality penalty.
        """
        logits, feat = y_pred
        return self.ce(logits, y_true) + self.reg_weight * orthogonality_penalty(feat)
