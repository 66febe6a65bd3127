"""`spiv.flow(..., progress=True)`: a tqdm bar over the pairs."""


def tqdm_bar(total):
    """A callable `(done, total)` that moves a tqdm bar of `total` pairs and
    closes it at the end."""
    try:
        from tqdm.auto import tqdm
    except ImportError as e:  # pragma: no cover - the message is the point
        raise ImportError("progress=True needs tqdm: pip install tqdm, "
                          "or pass a callable progress(done, total)") from e
    bar = tqdm(total=total, unit="pair")

    def tell(done, total):
        bar.update(done - bar.n)
        if done >= total:
            bar.close()

    return tell
