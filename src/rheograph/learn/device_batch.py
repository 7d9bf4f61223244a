"""Graph sets collated once and kept on the training device; mini-batches built there by indexing.

PyG's ``DataLoader`` collates every mini-batch from a Python list of ``Data`` objects on the CPU and the
trainer then copies it to the device: at a few hundred nodes per graph that per-batch work, not the
network, sets the epoch time (on a GPU most of it). ``DeviceGraphSet`` collates the whole set once into
one ``Batch`` on the device and builds the batch of any list of graph ids from it with index operations
(per-graph node and edge ranges from the slice arrays, ``repeat_interleave``, ``edge_index`` re-offset):
the result equals ``Batch.from_data_list`` of the same graphs, field by field and in the same order.

``device_loader`` wraps it in a ``torch.utils.data.DataLoader`` over graph ids, so that batch order and
shuffling are the ones PyG's loader of the same batch size draws from torch's seeded generator (and
Lightning's distributed sampler shards the ids under DDP, as it shards a PyG loader's dataset).
"""

from __future__ import annotations

import torch
from torch_geometric.data import Batch


def _exclusive_cumsum(counts: torch.Tensor) -> torch.Tensor:
    """(B,) counts -> (B,) starts: 0, c0, c0 + c1, ..."""
    return torch.cumsum(counts, dim=0) - counts


def _slices(counts: torch.Tensor) -> torch.Tensor:
    """(B,) counts -> (B + 1,) PyG slice array: 0, c0, c0 + c1, ..."""
    return torch.cat([counts.new_zeros(1), torch.cumsum(counts, dim=0)])


class DeviceGraphSet:
    """``graphs`` (a sequence of ``Data`` with the same fields) collated once into one ``Batch`` on
    ``device``. ``batch(ids)`` is ``Batch.from_data_list([graphs[i] for i in ids])`` built on the device;
    ``len`` is the number of graphs."""

    def __init__(self, graphs, device: torch.device | str = "cpu"):
        graphs = [graphs[k] for k in range(len(graphs))]
        if not graphs:
            raise ValueError("DeviceGraphSet needs at least one graph")
        self.device = torch.device(device)
        self.base_cls = type(graphs[0])
        whole = Batch.from_data_list(graphs)
        self.num_graphs = len(graphs)
        # the fields in the order PyG's collation stores them (batch and ptr are rebuilt, not gathered)
        self.keys = [k for k in whole._store.keys() if k not in ("batch", "ptr")]
        self.cat_dims = {k: whole.__cat_dim__(k, whole[k]) for k in self.keys}
        self.values = {k: whole[k].to(self.device) for k in self.keys}
        # fields concatenated alike (x and pos per node, edge_index and edge_attr per edge, the rest one
        # row per graph) share one slice array: their gather positions are computed once per batch
        self.group_of, slices_of_group = {}, []
        for key in self.keys:
            slices = whole._slice_dict[key]
            group = next((g for g, s in enumerate(slices_of_group) if torch.equal(s, slices)), None)
            if group is None:
                group = len(slices_of_group)
                slices_of_group.append(slices)
            self.group_of[key] = group
        # row counts per graph and group: on the CPU (batch sizes without a device sync) and the device
        self.counts_cpu = [s[1:] - s[:-1] for s in slices_of_group]
        self.starts = [s[:-1].to(self.device) for s in slices_of_group]
        self.counts = [c.to(self.device) for c in self.counts_cpu]
        # incremented fields hold node ids (edge_index): shifted by the nodes of the graphs before
        incs = {k: torch.as_tensor(whole._inc_dict[k]) for k in self.keys}
        self.inc_of = {k: incs[k].to(self.device) for k in self.keys if bool(torch.any(incs[k] != 0))}
        for key in self.inc_of:
            if not torch.equal(incs[key], whole.ptr[:-1]):
                raise ValueError(f"DeviceGraphSet: field {key} is incremented by other counts than nodes")
        self.node_counts_cpu = whole.ptr[1:] - whole.ptr[:-1]
        self.node_counts = self.node_counts_cpu.to(self.device)

    def __len__(self) -> int:
        return self.num_graphs

    def batch(self, ids) -> Batch:
        """The ``Batch`` of graphs ``ids`` (a sequence or 1-D tensor of graph indices), on the device."""
        ids_cpu = torch.as_tensor(ids, dtype=torch.long).cpu()
        ids = ids_cpu.to(self.device)
        size = ids_cpu.numel()
        gathers = []  # per group: (positions along the concatenation dimension, rows per graph)
        for starts, counts, counts_cpu in zip(self.starts, self.counts, self.counts_cpu):
            total = int(counts_cpu[ids_cpu].sum())
            selected = counts[ids]
            offset = torch.arange(total, device=self.device) - torch.repeat_interleave(
                _exclusive_cumsum(selected), selected, output_size=total
            )
            gathers.append(
                (torch.repeat_interleave(starts[ids], selected, output_size=total) + offset, selected)
            )
        node_counts = self.node_counts[ids]
        node_starts = _exclusive_cumsum(node_counts)
        out = Batch(_base_cls=self.base_cls)
        slice_dict, inc_dict = {}, {}
        for key in self.keys:
            positions, counts = gathers[self.group_of[key]]
            value = self.values[key].index_select(self.cat_dims[key], positions)
            if key in self.inc_of:  # edge_index: node ids of the whole set -> of this batch
                value = value - torch.repeat_interleave(
                    self.inc_of[key][ids] - node_starts, counts, output_size=positions.numel()
                )
                inc_dict[key] = node_starts
            else:
                inc_dict[key] = torch.zeros(size, dtype=torch.long, device=self.device)
            out[key] = value
            slice_dict[key] = _slices(counts)
        total_nodes = int(self.node_counts_cpu[ids_cpu].sum())
        out.batch = torch.repeat_interleave(
            torch.arange(size, device=self.device), node_counts, output_size=total_nodes
        )
        out.ptr = _slices(node_counts)
        out._num_graphs = size
        out._slice_dict = slice_dict
        out._inc_dict = inc_dict
        return out

    def __call__(self, ids) -> Batch:
        """A ``DataLoader``'s ``collate_fn``: the batch of the list of ids it hands over."""
        return self.batch(ids)


def device_loader(graph_set: DeviceGraphSet, batch_size: int, shuffle: bool) -> torch.utils.data.DataLoader:
    """Batches of ``graph_set`` as PyG's ``DataLoader(graphs, batch_size, shuffle)`` yields them (same
    ids per batch, same order for the same torch seed), built on the set's device; no worker processes."""
    return torch.utils.data.DataLoader(
        range(len(graph_set)), batch_size=batch_size, shuffle=shuffle, collate_fn=graph_set
    )
