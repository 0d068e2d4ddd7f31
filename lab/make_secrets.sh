#!/bin/sh
# Passwords for the secure lab profile (lab/secure.toml): one file per identity in lab/secrets/
# and the hub's usrpwd dictionary (user:password lines). Nothing here is committed
# (lab/secrets/ is in .gitignore). Copy each robot's file to that robot's computer only.
set -eu
cd "$(dirname "$0")"
mkdir -p secrets
chmod 700 secrets
: > secrets/users.txt
for user in controller operator r1 r2 r3 r4 r5 r6; do
    [ -f "secrets/$user.pw" ] || openssl rand -hex 16 > "secrets/$user.pw"
    echo "$user:$(cat "secrets/$user.pw")" >> secrets/users.txt
done
chmod 600 secrets/*
echo "lab/secrets: $(ls secrets | wc -l) files"
