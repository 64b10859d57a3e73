# One image for both compose services (rig-sim and server): shakeid with its compiled simulator kernel.
FROM python:3.11-slim
RUN apt-get update && apt-get install -y --no-install-recommends gcc libc6-dev \
    && rm -rf /var/lib/apt/lists/*
WORKDIR /app
COPY . .
RUN pip install --no-cache-dir . && useradd --create-home shakeid && mkdir -p /data && chown shakeid /data
USER shakeid
EXPOSE 8000 5020 5021
CMD ["shakeid", "serve", "--host", "0.0.0.0"]
