# dexlabel API and worker image (the same image runs both; the command picks the role).
FROM python:3.11-slim

ENV PYTHONDONTWRITEBYTECODE=1 PYTHONUNBUFFERED=1 PIP_NO_CACHE_DIR=1
RUN apt-get update \
    && apt-get install -y --no-install-recommends libgl1 libglib2.0-0 curl \
    && rm -rf /var/lib/apt/lists/*

WORKDIR /app
# PyTorch first, so its large layer is cached; pass TORCH_INDEX_URL to pick a CPU-only or a
# specific CUDA build from a wheel index of your choice.
ARG TORCH_INDEX_URL=""
RUN pip install torch==2.13.0 ${TORCH_INDEX_URL:+--index-url "$TORCH_INDEX_URL"}
COPY pyproject.toml README.md ./
COPY backend ./backend
COPY worker ./worker
COPY frontend ./frontend
COPY migrations ./migrations
RUN pip install -e .

RUN useradd --create-home --uid 1000 dexlabel && mkdir -p /app/var && chown dexlabel /app/var
USER dexlabel
# Safe by default: the image serves in prod mode, which refuses to start without a real
# DEXLABEL_SECRET_KEY (32+ random characters) and real DEXLABEL_MARKET_REQUESTERS key pairs,
# so a container never answers on all interfaces with development settings. For a local look,
# run it with -e DEXLABEL_ENV=dev (the instance then makes its own random secret in /app/var).
ENV DEXLABEL_ENV=prod
EXPOSE 8000
CMD ["dexlabel", "serve", "--host", "0.0.0.0", "--port", "8000"]
